"""Host: K instances of one environment, answering requests as one server (K >= 1).

One instance is a host of one: nothing asks "single or several?". A request enters by one
door, :meth:`Host.answer`, whatever carried it (a socket, or this process for
``rlenv_client.LocalClient``):

- a plain request goes to instance 0;
- ``batch`` carries one request per instance, each answered on its own;
- ``steps`` steps every instance in columns.

Each is checked whole by the records of :mod:`rlenv.serving._parts`, then served by
:meth:`Instance.serve <rlenv.serving._instance.Instance.serve>`. The host also owns the loop
(:meth:`Host.serve_forever`): in lockstep it waits for requests and the tree stands still; in
real time it wakes when an instance's next tick is due, and runs every tick that came due
before it answers.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from gymnasium.vector.utils import batch_space

from rlenv.environment import RLEnvironment
from rlenv.protocol import ErrorReply, GroupSpec, Hello, Reply, Request, Response
from rlenv.protocol.errors import ErrorCode, RequestError
from rlenv.protocol.spaces import compile_check
from rlenv.scene2d.packed_scene import MAX_DEPTH, MAX_NODES
from rlenv.serving._actions import MAX_REPEAT_ACTION
from rlenv.serving._agents_in_play import LOCKSTEP_ONLY, AgentsInPlay
from rlenv.serving._claims import Requester
from rlenv.serving._columns import Columns
from rlenv.serving._endpoint import Endpoint, Peer
from rlenv.serving._instance import Episode, Instance, failure, load_environment
from rlenv.serving._lean import LeanSteps
from rlenv.serving._parts import HostPart, dispatch, plan_for, shape_of, takes_control
from rlenv.serving._recent import KEEP_EVENTS
from rlenv.serving.policy_driver import DrivenAgents, Policy, PolicyDriver

__all__ = ["REQUEST_LIMITS", "Host", "Prepared", "target_of"]

logger = logging.getLogger(__name__)

REQUEST_LIMITS: Mapping[str, int] = {
    "max_repeat_action": MAX_REPEAT_ACTION,
    "max_level_nodes": MAX_NODES,
    "max_level_depth": MAX_DEPTH,
}
"""What one request may ask of an environment, as the hello's ``limits`` announce it (2.6)
beside the endpoint's sizes and deadlines: the ticks of one action, and a level's nodes and
their nesting (:mod:`rlenv.scene2d.packed_scene`); beyond them a request is refused with
``bad_request`` before anything runs."""


def target_of(environment: RLEnvironment | type[RLEnvironment] | str) -> str | None:
    """The ``MODULE:CLASS`` another server of this environment is started with, if there is one.

    ``None`` for an environment object (built by code of its own) and for a class that
    :func:`~rlenv.serving._instance.load_environment` cannot find by name (defined in
    ``__main__``, or inside a function or another class).
    """
    if isinstance(environment, str):
        return environment
    if not isinstance(environment, type):
        return None
    module, name = environment.__module__, environment.__qualname__
    return None if module == "__main__" or "." in name or "<" in name else f"{module}:{name}"


class Prepared:
    """A request whose every part was checked, ready to run.

    Attributes:
        request: the request.
        part: the part that addresses every instance (``batch``, ``steps``), or ``None`` for a
            request to the first instance.
        checked: what the checks made of it (a plan, for one instance).
    """

    __slots__ = ("checked", "part", "request")

    def __init__(self, request: Request, part: HostPart | None, checked: Any) -> None:
        self.request, self.part, self.checked = request, part, checked

    @property
    def takes_control(self) -> bool:
        """Whether the request changes the environment (only its controller may send it)."""
        if self.part is not None:
            return self.part.takes_control(self.request, self.checked)
        return takes_control(self.request.parts)


class Host:
    """``count`` instances of an environment, each in its own tree, answering as one.

    Args:
        environment: the environment class, ``MODULE:CLASS``, or (for one instance) an
            environment object.
        count: how many instances.
        clock: the trees' clock, for real-time mode.
        record_dir: where clients may have the environments record videos.
        real_time: start in real-time mode.
        policies: what drives agents (a loaded policy file, or ``"heuristic"``), by agent
            name, in every instance (lockstep; one instance when they drive every agent; see
            :mod:`rlenv.serving.policy_driver`).
        max_episode_steps: with every agent driven, steps after which an episode is cut short.
        keep_episodes: how many finished episodes each instance keeps as recordings, from the
            start (0: none, ever; ``None``: 8, once a client asks for them; see
            :mod:`rlenv.serving._recent`). They hold at most
            :data:`~rlenv.serving._recent.KEEP_EVENTS` events in all, shared by the instances.

    Attributes:
        driver: plays episodes between requests when policies drive every agent, else
            ``None``.

    Raises:
        ValueError: ``count`` is smaller than 1.
        TypeError: several instances of an environment object.
        RuntimeError: the environment has no agent, world or spaces.
        ValueError: ``policies`` in real time, or driving every agent of several instances; a
            policy for an agent the environment lacks, or whose spaces are not its agent's; a
            heuristic for an agent whose class defines none.
    """

    def __init__(
        self,
        environment: RLEnvironment | type[RLEnvironment] | str,
        count: int = 1,
        *,
        clock: Callable[[], float] = time.monotonic,
        record_dir: Path | None = None,
        real_time: bool = False,
        policies: Mapping[str, Policy] | None = None,
        max_episode_steps: int | None = None,
        keep_episodes: int | None = None,
    ) -> None:
        target = target_of(environment)
        if isinstance(environment, str):
            environment = load_environment(environment)
        if count < 1:
            raise ValueError("a host holds at least one instance")
        if count > 1 and not isinstance(environment, type):
            raise TypeError("several instances need the environment class, not an instance")
        self.instances = [
            Instance(environment, dispatch, clock, record_dir, keep_episodes, KEEP_EVENTS // count)
            for _ in range(count)
        ]
        self.requester = Requester()  # who sent the request being served (for claims)
        for instance in self.instances:
            instance.requester = self.requester
        first = self.instances[0]
        self.hello = Hello(
            environment=first.environment.name,
            action_space=first.action_space,
            observation_space=first.observation_space,
            agents=tuple(agent.name for agent in first.roster.actors()),
            physics_ticks_per_second=first.tree.physics_ticks_per_second,
            repeat_action=first.environment.repeat_action,
            render_modes=("rgb_array",),
            render_size=first.environment.render_size,
            instances=count,
            limits=dict(REQUEST_LIMITS),
            target=target,
            possible_agents=(
                first.roster.hello_classes() if isinstance(first.roster, AgentsInPlay) else None
            ),
            groups={
                members.group.name: GroupSpec(
                    members.group.instance_count,
                    members.group.member_observation_space,
                    members.group.member_action_space,
                )
                for members in first.roster.groups
            },
        )
        self.steps_action_space = batch_space(first.action_space, count)
        self.steps_action = compile_check(self.steps_action_space, "steps.action")
        self.columns = Columns(first.observation_space, isinstance(first.roster, AgentsInPlay))
        self.lean = LeanSteps(self.instances) if LeanSteps.serves(self.instances) else None
        self._clocked: list[Instance] = []  # those in real time: each instance tells (below)
        for instance in self.instances:
            instance.real_time_changed = self._follow_real_time
            if real_time:
                if isinstance(instance.roster, AgentsInPlay):
                    raise ValueError(f"--real-time {LOCKSTEP_ONLY}")
                instance.set_real_time(True)
        self._after_send_hooks = any(instance.has_after_send for instance in self.instances)
        self.driver: PolicyDriver | None = None
        if policies:
            self._drive(policies, max_episode_steps, real_time)

    def _drive(
        self, policies: Mapping[str, Policy], max_episode_steps: int | None, real_time: bool
    ) -> None:
        """Let ``policies`` drive their agents in every instance; a driver when they drive all."""
        if real_time:
            raise ValueError("--policy drives agents in lockstep: leave out --real-time")
        driven = [DrivenAgents(policies, instance.roster.actors()) for instance in self.instances]
        for instance, agents in zip(self.instances, driven, strict=True):
            instance.drive(agents)
        first = self.instances[0]
        self.hello.driven = tuple(
            agent.name for agent in first.roster.actors() if agent.name in driven[0].names
        )
        if driven[0].every_agent:
            if len(self.instances) > 1:
                raise ValueError(
                    "--policy drives every agent, so the server plays one "
                    "instance itself: leave out --instances"
                )
            self.driver = PolicyDriver(self.answer, first, driven[0], max_episode_steps)

    def answer(self, request: Request) -> Reply:
        """The one answer to ``request`` (plain, batch or steps); a refusal changes nothing.

        The answer counts as sent once returned (the environments' ``_after_send_response``
        has run).
        """
        prepared = self.prepare(request)
        if prepared.__class__ is ErrorReply:
            return prepared
        reply = self.run(prepared)  # type: ignore[arg-type]
        self.after_send(prepared)  # type: ignore[arg-type]
        return reply

    def prepare(self, request: Request) -> Prepared | ErrorReply:
        """Check every part of ``request`` before anything moves; its refusal, if refused.

        Instances in real time first run the ticks that came due, so that the checks see the
        current state.
        """
        self.catch_up()
        parts = request.parts
        try:
            shape = shape_of(parts)
            host_part = shape.host_part
            if host_part is None:
                return Prepared(request, None, plan_for(self.instances[0], parts, shape))
            return Prepared(request, host_part, host_part.check(self, request))
        except RequestError as error:
            return ErrorReply(request.id, error.code, str(error))
        except Exception as error:  # user code (a check_config of its own) raised
            return failure(
                request.id, error, "raised while checking the request; nothing was applied"
            )

    def run(self, prepared: Prepared, reports: bool = True) -> Reply:
        """Serve a checked request; its answer.

        Unless it ``reports`` (it goes to a client that does not control the environment), the
        answer carries no reward nor ticks: they stay for the controller's next answer.
        """
        request = prepared.request
        parts = request.parts
        if prepared.part is not None:
            return prepared.part.run(self, request, prepared.checked, reports)
        if not parts:
            return Response(request.id)  # nothing asked (the token, say)
        return self.instances[0].serve(prepared.checked, request.id, reports)

    def after_send(self, prepared: Prepared) -> None:
        """Tell the environments that served ``prepared`` that its answer went out."""
        if not self._after_send_hooks:
            return
        part = prepared.part
        if part is None:
            self.instances[0].after_send()
            return
        for instance in part.served(self, prepared.checked):
            instance.after_send()

    def abandon(self, why: str) -> None:
        """End every instance's episode where it stands (a request was cut short half way).

        The next action is refused with ``reset_required``, saying ``why``; the next reset
        rebuilds the environments (their code was stopped half way).
        """
        for instance in self.instances:
            if instance.state is not Episode.NOT_STARTED:
                instance.mark_broken(why)
                instance.abandon_episode(why)

    def catch_up(self) -> None:
        """Run the ticks that came due on the instances in real time."""
        for instance in self._clocked:
            instance.catch_up()

    def time_to_next_tick(self) -> float | None:
        """Seconds until the next tick of an instance in real time (``None``: none is)."""
        waits = [
            wait for instance in self._clocked if (wait := instance.time_to_next_tick()) is not None
        ]
        return min(waits, default=None)

    def _follow_real_time(self) -> None:
        """An instance switched real time (whoever asked): which ones tick by the clock now."""
        self._clocked = [instance for instance in self.instances if instance.tree.real_time]

    def serve_forever(self, endpoint: Endpoint) -> None:
        """Answer the endpoint's requests until interrupted; in real time, tick meanwhile.

        With a :attr:`driver`, the policies play one step whenever no request is waiting, and
        nobody may take control.
        """
        endpoint.on_drop = self.release_claims
        driver = self.driver
        if driver is not None:
            endpoint.reserve(
                "its agents are driven by policies (rlenv serve --policy); only observing is open"
            )
            while True:
                got = endpoint.receive(driver.wait())
                if got is None:
                    driver.step()
                else:
                    self.handle(endpoint, *got)
        while True:
            got = endpoint.receive(self.time_to_next_tick() if self._clocked else None)
            if got is None:
                self.catch_up()
                continue
            self.handle(endpoint, *got)

    def handle(self, endpoint: Endpoint, peer: Peer, request: Request) -> None:
        """Answer one request that came through ``endpoint``.

        A request is checked first: a refusal is answered and changes nothing, control
        included. A request that changes the environment then needs its client to control it
        (the endpoint answers ``busy`` otherwise). Once the answer went out, the environments
        that served it hear of it (``_after_send_response``).

        No request ends the server: an exception that escapes everything else (a bug of the
        server's) is logged and answered with ``environment_error``, and the server serves on.
        """
        answered = False
        self.requester.peer = peer
        try:
            prepared = self.prepare(request)
            if isinstance(prepared, ErrorReply):
                answered = True
                endpoint.reply(peer, prepared)
                return
            if endpoint.controls(peer):
                reply = self.run(prepared)
            elif not prepared.takes_control:
                reply = self.run(prepared, reports=False)
            elif endpoint.take_control(peer, request.id):
                self.release_claims(peer)  # it acts for every agent now
                reply = self.run(prepared)
            else:
                return  # answered busy
            answered = True
            endpoint.reply(peer, reply)
            self.after_send(prepared)
        except Exception as error:  # the last resort: this request fails, not the server
            logger.error("serving request %r raised", request.id, exc_info=error)
            if not answered:  # one answer per request, or the client loses the thread
                endpoint.reply(
                    peer,
                    ErrorReply(
                        request.id,
                        ErrorCode.ENVIRONMENT_ERROR,
                        f"the server failed answering this request ({type(error).__name__}: "
                        f"{error}); it serves on, but what the request changed is not known",
                    ),
                )
        finally:
            self.requester.peer = None

    def release_claims(self, peer: object) -> None:
        """End the claims ``peer`` holds (it left, or took control; :mod:`._claims`)."""
        for instance in self.instances:
            if instance.claims is not None:
                instance.release_claim(peer)

    def close(self) -> None:
        """Take every environment out of its tree."""
        for instance in self.instances:
            instance.close()
