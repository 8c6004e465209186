"""Real-time mode: ticks follow the clock (a manual one here: no test sleeps)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from conftest import Serve

from rlenv.protocol import Request
from rlenv.testing import ManualClock
from rlenv_client import Client, ErrorCode, LocalClient, RemoteError

TARGET = "examples.cartpole:CartPoleEnvironment"
STILL = np.zeros(1, np.float32)
POLE = "World/Physics/Pole"


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock()


@pytest.fixture
def live(clock: ManualClock) -> LocalClient:
    client = LocalClient(TARGET, clock=clock)
    client.configure(real_time=True)
    return client


def test_ticks_follow_the_clock_not_the_client(live: LocalClient, clock: ManualClock) -> None:
    live.reset(seed=0)
    _, _, _, _, info = live.step(STILL)
    assert info["frames"] == 0 and info["late"] is False  # no time passed, no tick
    clock.advance(0.1)  # 6 ticks at 60 per second, while the client was away
    _, reward, _, _, info = live.step(STILL)
    assert info["frames"] == 6 and reward == 6.0
    assert info["late"] is True and info["late_actions"] == 1  # 6 ticks > repeat_action 4
    clock.advance(3 / 60)
    _, _, _, _, info = live.step(STILL)
    assert info["frames"] == 3 and info["late"] is False and info["late_actions"] == 1


def test_actions_apply_when_they_arrive(live: LocalClient, clock: ManualClock) -> None:
    live.reset(seed=0)
    live.step(np.ones(1, np.float32))  # push right from now on
    clock.advance(0.2)
    pushed, *_ = live.step(np.ones(1, np.float32))
    live.reset(seed=0)
    live.step(STILL)
    clock.advance(0.2)
    idle, *_ = live.step(STILL)
    assert pushed[3] > idle[3] + 0.1  # the cart moved right faster under the push


def test_an_episode_that_ends_between_requests_is_reported_once(
    live: LocalClient, clock: ManualClock
) -> None:
    live.reset(seed=0)
    live.step(np.ones(1, np.float32))
    clock.advance(5.0)  # the pole falls long before this
    _, _, terminated, _, info = live.step(np.ones(1, np.float32))
    assert terminated and 0 < info["frames"] < 300  # it stopped when the pole fell
    with pytest.raises(RemoteError) as error:
        live.step(STILL)
    assert error.value.code == ErrorCode.RESET_REQUIRED
    live.reset(seed=1)


def test_snapshots_need_lockstep(live: LocalClient) -> None:
    live.reset(seed=0)
    with pytest.raises(RemoteError, match="snapshots need lockstep"):
        live.snapshot()
    live.configure(real_time=False)
    live.snapshot()


def test_a_real_time_server_keeps_running(serve: Serve) -> None:
    """Over a real socket, with the wall clock: the episode runs on while the client only reads."""
    server = serve(args=["--real-time"])
    with Client(server.host, server.port, timeout=10) as client:
        assert client.get_property(".", "real_time") is True
        client.reset(seed=0)
        start = client.get_property(POLE, "angle")
        deadline = time.monotonic() + 30
        while (current := client.stats()["current"])["ticks"] < 30:  # reads, never steps
            assert time.monotonic() < deadline, f"the ticks stood still: {current}"
        assert current["length"] == 0  # no step was sent: the clock ran them
        assert current["return"] == current["ticks"]  # +1 for every tick the pole stayed up
        assert client.get_property(POLE, "angle") != start  # the pole moved under gravity


def test_steps_in_columns_follow_the_clock_too(clock: ManualClock) -> None:
    """Steps run the ticks due by the clock first, as a plain request does: the same frames,
    rewards and lateness."""
    with (
        LocalClient(TARGET, clock=clock, instances=2) as many,
        LocalClient(TARGET, clock=clock) as one,
    ):
        one.configure(real_time=True)
        real_time = Request(0, {"config": {"environment": {"real_time": True}}})
        for request in (real_time, many.reset_request(seed=4)):
            many.send_batch([request] * 2)
            many.receive_batch()
        one.reset(seed=4)
        clock.advance(0.1)
        many.send_steps(np.zeros((2, 1), np.float32))
        columns = many.receive_steps()
        _, reward, _, _, info = one.step(STILL)
    assert info["frames"] >= 6
    assert columns.frames.tolist() == [info["frames"]] * 2
    assert columns.reward.tolist() == [reward] * 2
    assert [each["late"] for each in columns.info] == [info["late"]] * 2


def test_every_answer_reports_the_ticks_since_the_previous_one(
    live: LocalClient, clock: ManualClock
) -> None:
    """An observation answers for the ticks it saw too, so no tick goes unaccounted."""
    live.reset(seed=0)
    clock.advance(0.1)  # 6 ticks
    observation = live._call(observation={"agent": {}})
    assert observation.frames == 6 and observation.reward == 6.0
    clock.advance(3 / 60)
    _, reward, _, _, info = live.step(STILL)
    assert info["frames"] == 3 and reward == 3.0


def test_an_answer_to_an_observer_leaves_the_ticks_to_the_controller(clock: ManualClock) -> None:
    """What the host runs for a client that does not control the environment reports no
    reward nor ticks: they stay for the controller's next answer, none lost, none twice."""
    from rlenv.serving._host import Host

    host = Host(TARGET, clock=clock, real_time=True)
    host.answer(Request(1, {"reset": {"seed": 0}}))
    clock.advance(0.1)  # 6 ticks
    for request_id in (2, 3):
        prepared = host.prepare(Request(request_id, {"observation": {"agent": {}}}))
        observed = host.run(prepared, reports=False)  # type: ignore[arg-type]
        assert (observed.frames, observed.reward) == (0, 0.0)  # type: ignore[union-attr]
    clock.advance(2 / 60)
    answer = host.answer(Request(4, {"observation": {"agent": {}}}))
    assert (answer.frames, answer.reward) == (8, 8.0)  # type: ignore[union-attr]
    host.close()


def test_observers_of_a_real_time_server_take_no_ticks_from_the_controller(serve: Serve) -> None:
    server = serve(args=["--real-time"])
    with (
        Client(server.host, server.port, timeout=10) as controller,
        Client(server.host, server.port, timeout=10) as observer,
    ):
        start, _ = controller.reset(seed=0)
        observed, deadline = start, time.monotonic() + 10
        while observed.tobytes() == start.tobytes():  # until the server ticked (no sleep)
            assert time.monotonic() < deadline, "the real-time server never ticked"
            answer = observer._call(observation={"agent": {}})
            assert (answer.frames, answer.reward) == (0, 0.0)
            observed = observer._observation(answer)
        answer = controller._call(observation={"agent": {}})
        assert answer.frames >= 1 and answer.reward > 0


# --- real time switched by anyone (issue 43, item 1) --------------------------------------------


def _ticks_run(client: Client, at_least: int, message: str) -> None:
    """Poll the statistics (never stepping) until the episode ran ``at_least`` ticks (the
    controller's answers count them)."""
    deadline = time.monotonic() + 30
    while client.stats()["current"]["ticks"] < at_least:
        assert time.monotonic() < deadline, message


def test_an_observer_switching_one_of_two_instances_to_lockstep_ends_nothing(serve: Serve) -> None:
    """Before, the host kept its list of instances in real time apart, and rebuilt it for
    ``config``, ``batch`` and ``restore`` only: the next wait took ``min(float, None)`` and the
    process ended."""
    server = serve(args=["--instances", "2", "--real-time"])
    with (
        Client(server.host, server.port, timeout=10) as controller,
        Client(server.host, server.port, timeout=10) as observer,
    ):
        controller.reset(seed=0)
        observer.inspect_configure(real_time=False)
        assert observer.get_property(".", "real_time") is False
        controller.send_batch([None, controller.reset_request(seed=1)])
        controller.receive_batch()
        assert server.is_alive()
        observer.inspect_configure(real_time=True)  # and back: instance 0 follows the clock
        _ticks_run(controller, 3, "instance 0 did not tick after it was switched back")
        assert server.is_alive()


def test_a_per_client_server_survives_one_client_switching_real_time(serve: Serve) -> None:
    """Every client's environments shared the process that the crash ended."""
    server = serve(args=["--per-client", "--instances", "2", "--real-time"])
    with (
        Client(server.host, server.port, timeout=10) as first,
        Client(server.host, server.port, timeout=10) as second,
    ):
        first.reset(seed=0)
        second.reset(seed=0)
        first.inspect_configure(real_time=False)
        first.step(STILL)  # lockstep now: the action runs its ticks
        _ticks_run(second, 3, "the other client's environment stopped ticking")
        second.step(STILL)
        assert server.is_alive()


def test_an_inspector_switching_a_lockstep_server_to_real_time_starts_its_clock(
    serve: Serve,
) -> None:
    """Before, the clock stayed stopped: 0 ticks in a second."""
    server = serve()
    with (
        Client(server.host, server.port, timeout=10) as controller,
        Client(server.host, server.port, timeout=10) as observer,
    ):
        controller.reset(seed=0)
        observer.inspect_configure(real_time=True)
        _ticks_run(controller, 30, "switched to real time by an inspector, the server never ticked")


def test_a_steps_request_starting_real_time_starts_the_clock(clock: ManualClock) -> None:
    from rlenv.serving._host import Host

    host = Host(TARGET, 2, clock=clock)
    real_time = {"config": {"environment": {"real_time": True}}, "reset": {"seed": 3}}
    host.answer(
        Request(
            1,
            {
                "steps": {
                    "action": np.zeros((2, 1), np.float32),
                    "reset": [True, True],
                    "reset_with": [real_time, None],
                }
            },
        )
    )
    assert host.time_to_next_tick() is not None  # the host follows the clock of instance 0
    clock.advance(0.1)
    host.catch_up()
    answer = host.answer(Request(2, {"observation": {"agent": {}}}))
    assert answer.frames >= 6  # type: ignore[union-attr]  # 0.1 s at 60 ticks a second
    host.close()


def test_a_tick_that_raises_between_requests_ends_the_episode_not_the_server(serve: Serve) -> None:
    """In real time user code runs between requests too: an exception there is the episode's,
    not the process's."""
    server = serve("examples.faulty:FaultyEnvironment", args=["--real-time"])
    with Client(server.host, server.port, timeout=10) as client:
        client.reset()
        client.step(1)  # FaultyAgent's tick raises under action 1: the next tick due
        deadline = time.monotonic() + 30
        with pytest.raises(RemoteError) as stopped:
            while True:
                assert time.monotonic() < deadline, "the raising tick never ran"
                client.step(0)
        assert stopped.value.code in (ErrorCode.RESET_REQUIRED, ErrorCode.ENVIRONMENT_ERROR)
        assert server.is_alive()
        client.reset()
        client.stats()
        assert server.is_alive()


def test_several_agents_follow_the_clock_an_observer_switched_on(clock: ManualClock) -> None:
    """The same with two agents (examples/pair): an inspector's switch, whoever sends it, is the
    host's to follow; each agent's outcome counts the ticks."""
    from examples.pair import TARGET as PAIR
    from rlenv.serving._host import Host

    host = Host(PAIR, clock=clock)
    host.answer(Request(1, {"reset": {"seed": 2}}))
    switch = host.prepare(
        Request(2, {"inspect": {"configure": {"environment": {"real_time": True}}}})
    )
    host.run(switch, reports=False)  # type: ignore[arg-type]  # as to an observer
    assert host.time_to_next_tick() is not None
    clock.advance(0.1)
    answer = host.answer(Request(3, {"observation": {"agent": {}}}))
    assert answer.frames >= 6 and set(answer.agents) == {"Red", "Blue"}  # type: ignore[union-attr]
    host.answer(Request(4, {"config": {"environment": {"real_time": False}}}))
    assert host.time_to_next_tick() is None
    host.close()
