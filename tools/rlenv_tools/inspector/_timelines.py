"""The inspector's timelines: recordings to scrub, step, tick, branch and compare from the page.

:class:`Timelines` holds the :class:`~rlenv_tools.timeline.Timeline` of each recording the page
can open (files given to ``rlenv replay FILE --inspect``, or the recent episodes of a watched
instance, see :meth:`Timelines.open_recent`), each with its tree of branches, numbered in the
order they were made (branch 0 is the episode itself). A timeline is not thread-safe, and a
root and its branches share its processes: every call on one of them holds its root's lock. A
timeline is opened (its environment started, the episode re-simulated once) when the page
first asks for it.

Branches are made from the page with the agent's keys (its ``demonstration_keys``, the map the
page's Take control uses, :func:`~rlenv_tools.inspector._control.key_map`): the first key
press makes a branch of one action at the scrubbed step, each next press lengthens it by one
action (``branch(len(b), [action])``: the tree keeps it under its branch point); or with a
policy: ``policies={"name": callable}`` given from Python, or ``--policy FILE.onnx`` on the
command line (:class:`~rlenv.serving.onnx_policy.OnnxPolicy`, loaded once).

What the page gets is JSON: see :meth:`Timelines.step`, :meth:`Timelines.ticks`,
:meth:`Timelines.compare` and :meth:`Timelines.describe`.

The page's timelines are bounded: at most ``max_recent`` recent episodes and ``max_files``
recordings from files are open at once (past either, the oldest opened is closed: a recent
episode leaves the list, a file stays in it and is opened again when asked), and each open
timeline holds at most its share of the page's ``max_processes`` and ``max_memory``. A
recording's target is imported only where it is installed, unless the page was given a
``target`` or ``trust_target`` (:mod:`rlenv_client.trusted_targets`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from rlenv_client.replay import EpisodeFile
from rlenv_tools.inspector._recordings import Branch, Recordings, Root, episode_id
from rlenv_tools.inspector._timeline_errors import chosen_policy, key_action, page_call
from rlenv_tools.inspector._timeline_json import (
    agents_json,
    shown,
    side_json,
    state_json,
    ticks_json,
)
from rlenv_tools.inspector._watch import InspectorError, to_json
from rlenv_tools.timeline import Timeline

__all__ = ["MAX_BRANCH_STEPS", "MAX_TICKS", "Timelines", "episode_id"]

MAX_BRANCH_STEPS = 100_000
"""The most steps a policy's branch may take (``max_steps``)."""
MAX_TICKS = 100
"""The most ticks one answer of the tick view holds (``count``; a page of a long step)."""

Policy = Callable[[Any], Any]


class Timelines:
    """The timelines the page can open, their branches, and the policies to branch with.

    Args:
        paths: recordings (``episode-NNNN.rlenv`` files) to offer.
        policies: policies to branch with, by name (``callable(observation) -> action``).
        unavailable: policies that could not be loaded, by name: why (the page says so).
        target: the environment to serve (``MODULE:CLASS``; default: each recording's, where
            it is an installed package).
        trust_target: import each recording's target whatever it is (``--trust-target``).
        checkpoint_every: see :class:`~rlenv_tools.timeline.Timeline` (default: its own).
        max_recent: how many recent episodes of live instances stay open at once (the oldest
            opened is closed, with its branches, to make room).
        max_files: how many recordings from files stay open at once (the oldest opened is
            closed, with its branches; it stays offered, and opens again when asked).
        max_processes: the most processes the page's timelines hold in all (each open one
            gets an equal share).
        max_memory: the most memory (PSS, bytes) they hold in all (shared the same way).
    """

    def __init__(
        self,
        paths: Iterable[str | Path] = (),
        *,
        policies: Mapping[str, Policy] | None = None,
        unavailable: Mapping[str, str] | None = None,
        target: str | None = None,
        trust_target: bool = False,
        checkpoint_every: int | None = None,
        max_recent: int = 3,
        max_files: int = 3,
        max_processes: int = 1024,
        max_memory: int = 4 << 30,
    ) -> None:
        self.policies = dict(policies or {})
        self.unavailable = dict(unavailable or {})
        self._recordings = Recordings(
            target=target,
            trust_target=trust_target,
            checkpoint_every=checkpoint_every,
            max_recent=max_recent,
            max_files=max_files,
            max_processes=max_processes,
            max_memory=max_memory,
        )
        for path in paths:
            self.add_file(path)

    # --- which timelines -----------------------------------------------------------------------

    def add_file(self, path: str | Path) -> int:
        """Offer the recording at ``path`` (read now, opened when first asked); its number.

        Raises:
            ValueError: the file is not an rlenv episode.
        """
        return self._recordings.add_file(path)

    def add_episode(self, episode: EpisodeFile, name: str, origin: Mapping[str, Any]) -> int:
        """Offer ``episode`` (a live instance's recent one, say) as ``name``; its number."""
        return self._recordings.add(name, lambda: episode, dict(origin))

    def open_recent(
        self, episodes: list[EpisodeFile], server: int, instance: int, identifier: str
    ) -> dict[str, Any]:
        """Offer the recent episode whose :func:`episode_id` is ``identifier``; its description.

        An identifier, not a place in ``episodes``: the list moves on as episodes finish. It is
        looked for in ``episodes`` (the server's now), then in those last :meth:`listed`. The
        oldest recent one opened is closed past ``max_recent`` (and leaves the list).

        Raises:
            InspectorError: 404, no such episode (or no longer kept).
        """
        found = self._recordings.find_recent(episodes, server, instance, identifier)
        origin = {"server": server, "instance": instance, "recent": identifier}
        steps = sum(event[0] == "action" for event in found.snapshot["events"])
        number = self.add_episode(
            found,
            f"server {server} · instance {instance} · "
            f"recent episode of {steps} steps ({identifier[:6]})",
            origin,
        )
        return self.describe(number)

    def listed(self, server: int, instance: int, episodes: list[EpisodeFile]) -> None:
        """Remember the recent ``episodes`` the page was shown for an instance (the last 32).

        :meth:`open_recent` finds them even once the server has dropped them (a fast trainer
        finishes several episodes while a person reads the list).
        """
        self._recordings.listed(server, instance, episodes)

    def list(self) -> dict[str, Any]:
        """Every timeline offered (number, name, origin, whether open), and the policies."""
        roots = self._recordings.roots()
        return {
            "timelines": [
                {
                    "timeline": root.number,
                    "name": root.name,
                    "origin": root.origin,
                    "open": root.timeline is not None,
                    "error": root.error,
                }
                for root in roots
            ],
            "policies": sorted(self.policies),
            "unavailable": dict(self.unavailable),
        }

    def describe(self, number: int) -> dict[str, Any]:
        """One timeline (opened if it was not): its length, keys and tree of branches.

        Raises:
            InspectorError: 404 no such timeline; 422 its environment did not start, or
                re-simulated the recording differently.
        """
        with self._recordings.using(number) as root:
            return self._describe(root)

    # --- what the page shows ---------------------------------------------------------------------

    def step(self, number: int, branch: int, step: int) -> dict[str, Any]:
        """The state after ``step`` of ``branch``: what the page draws and lists.

        ``{"timeline", "branch", "step", "length", "reward", "terminated", "truncated",
        "info", "observation" (by agent, as the live page shows it: the agents of this answer),
        "agents_in_play" (the agents in play at this step, :meth:`~rlenv_tools.timeline
        .Timeline.agents_in_play`), "arrived" and "left" (those that joined, and left, at this
        step), "agent_returns" (each agent's return up to this step), "draw" (the scene's draw
        list), "properties" (every node's exported values, by path)}``.

        Raises:
            InspectorError: 404 no such timeline or branch; 400 no such step; 422 the
                timeline's environment failed.
        """
        with self._recordings.using(number) as root:
            timeline = self._branch(root, branch).timeline
            state = page_call(lambda: timeline.at(_step(timeline, step)))
            where = {"timeline": number, "branch": branch, "step": step}
            return {
                **where,
                "length": len(timeline),
                **state_json(state, root.agents),
                **agents_json(timeline, step),
            }

    def ticks(
        self, number: int, branch: int, step: int, first: int = 1, count: int = MAX_TICKS
    ) -> dict[str, Any]:
        """A page of the physics ticks inside ``step``'s action: ``count`` from tick ``first``.

        ``{"timeline", "branch", "step", "frames" (the ticks the action asked for), "first",
        "next" (the first tick of the next page, ``None`` after the last), "ticks": [...]}``,
        each tick with ``tick``, ``reward``, ``terminated``, ``truncated``, ``info``,
        ``observation``, ``properties`` and ``draw`` (the scene after the tick). A page holds
        at most :data:`MAX_TICKS`, so no answer (nor the timeline's lock) lasts long whatever
        the step's ``repeat_action``.

        Raises:
            InspectorError: as :meth:`step` (step 0 has no ticks: 400; ``first`` past the
                step's ticks, or ``count`` outside 1 to :data:`MAX_TICKS`: 400).
        """
        if not 1 <= count <= MAX_TICKS:
            raise InspectorError(400, f"count must be 1 to {MAX_TICKS}")
        with self._recordings.using(number) as root:
            timeline = self._branch(root, branch).timeline
            if not 1 <= step <= len(timeline):
                raise InspectorError(
                    400, f"step {step} has no action: steps 1 to {len(timeline)} have"
                )
            frames = timeline.frames(step)
            ticks = page_call(lambda: timeline.ticks(step, first=first, count=count))
            where = {"timeline": number, "branch": branch, "step": step}
            return {**where, **ticks_json(ticks, frames, first, count, root.agents)}

    def compare(self, number: int, first: int, second: int, step: int) -> dict[str, Any]:
        """Two branches side by side (``a``: ``first``, ``b``: ``second``).

        Each one's reward at every step, their first difference
        (:meth:`~rlenv_tools.timeline.Timeline.diff`), and at ``step`` each one's observation
        and reward and the second's observation minus the first's (``None`` where a branch does
        not reach ``step``).

        Raises:
            InspectorError: as :meth:`step` (a step neither reaches: 400).
        """
        with self._recordings.using(number) as root:
            a, b = self._branch(root, first), self._branch(root, second)
            if not 0 <= step <= max(len(a.timeline), len(b.timeline)):
                raise InspectorError(
                    400,
                    f"no step {step}: the branches have steps 0 to "
                    f"{max(len(a.timeline), len(b.timeline))}",
                )
            diff = self._diff(root, a, b)
            sides = {}
            for name, branch in (("a", a), ("b", b)):
                state = (
                    page_call(functools.partial(branch.timeline.at, step))
                    if step <= len(branch.timeline)
                    else None
                )
                sides[name] = side_json(branch, state, root.agents)
            reached = step < len(diff.observations)
            return {
                "timeline": number,
                "step": step,
                "a": sides["a"],
                "b": sides["b"],
                "first_difference": diff.first_difference,
                "difference": shown(diff.observations[step], root.agents) if reached else None,
            }

    # --- branching -------------------------------------------------------------------------------

    def branch_keys(self, number: int, branch: int, step: int, key: str) -> dict[str, Any]:
        """A new branch of ``branch`` at ``step``: one action, the agent's for ``key``.

        Returns the timeline's description with ``"branch"``: the new one's number.

        Raises:
            InspectorError: as :meth:`step`; 422 a key outside the agent's map (or none).
        """
        with self._recordings.using(number) as root:
            parent = self._branch(root, branch)
            action = key_action(root, key)
            _step(parent.timeline, step)
            made = page_call(lambda: parent.timeline.branch(step, [action]))
            new = self._add_branch(root, branch, step, "keys", made, [key])
            return {**self._describe(root), "branch": new.number}

    def extend(self, number: int, branch: int, key: str) -> dict[str, Any]:
        """Lengthen a key branch by one action, the agent's for ``key``.

        It keeps its number and its place in the tree.

        Raises:
            InspectorError: as :meth:`branch_keys`; 409 not a key branch, or its episode ended.
        """
        with self._recordings.using(number) as root:
            node = self._branch(root, branch)
            if node.how != "keys":
                raise InspectorError(
                    409,
                    f"branch {branch} is {node.describe()['label']}: "
                    "only a key branch grows key by key",
                )
            if node.timeline.ended:
                raise InspectorError(
                    409,
                    f"branch {branch}'s episode ended at step "
                    f"{len(node.timeline)}: branch from an earlier step",
                )
            action = key_action(root, key)
            timeline = node.timeline
            node.timeline = page_call(lambda: timeline.branch(len(timeline), [action]))
            node.actions.append(key)
            return {**self._describe(root), "branch": node.number}

    def branch_policy(
        self, number: int, branch: int, step: int, policy: str, max_steps: int
    ) -> dict[str, Any]:
        """A new branch of ``branch`` at ``step``, its actions chosen by ``policy``.

        At most ``max_steps`` of them; fewer where its episode ends.

        Raises:
            InspectorError: as :meth:`step`; 404 no such policy (or 422 one that could not be
                loaded, saying why); 422 the policy failed.
        """
        chosen = chosen_policy(self.policies, self.unavailable, policy)
        if not 1 <= max_steps <= MAX_BRANCH_STEPS:
            raise InspectorError(400, f"max_steps must be 1 to {MAX_BRANCH_STEPS}")
        with self._recordings.using(number) as root:
            parent = self._branch(root, branch)
            _step(parent.timeline, step)
            try:
                made = page_call(
                    lambda: parent.timeline.branch(step, policy=chosen, max_steps=max_steps)
                )
            except InspectorError:
                raise
            except Exception as error:  # the policy's own failure: the page says which
                raise InspectorError(422, f"policy {policy} failed: {error!r:.200}") from None
            new = self._add_branch(root, branch, step, "policy", made, [policy])
            return {**self._describe(root), "branch": new.number}

    def close(self) -> None:
        """Close every timeline (its processes end); safe to repeat."""
        self._recordings.close()

    # --- inside ----------------------------------------------------------------------------------

    def _branch(self, root: Root, number: int) -> Branch:
        self._recordings.opened(root)
        branch = root.branches.get(number)
        if branch is None:
            raise InspectorError(
                404,
                f"timeline {root.number} has no branch {number} "
                f"(branches 0 to {max(root.branches)})",
            )
        return branch

    def _add_branch(
        self, root: Root, parent: int, at: int, how: str, timeline: Timeline, actions: Sequence[str]
    ) -> Branch:
        number = max(root.branches) + 1
        root.branches[number] = Branch(number, parent, at, how, timeline, list(actions))
        return root.branches[number]

    def _describe(self, root: Root) -> dict[str, Any]:
        timeline = self._recordings.opened(root)
        return {
            "timeline": root.number,
            "name": root.name,
            "origin": root.origin,
            "target": timeline.episode.target,
            "length": len(timeline),
            "ended": timeline.ended,
            "agents": root.agents,
            "agents_in_play": timeline.agents.in_play(),
            "departures": timeline.agents.departures(),
            "agent_returns": to_json(timeline.agents.returns()),
            "keys": list(root.keys),
            "keys_error": root.keys_error,
            "policies": sorted(self.policies),
            "unavailable": dict(self.unavailable),
            "branches": [branch.describe() for branch in root.branches.values()],
        }

    def _diff(self, root: Root, a: Branch, b: Branch) -> Any:
        kept = root.diffs.get((a.number, b.number))
        if kept is None or kept[0] is not a.timeline or kept[1] is not b.timeline:
            kept = (a.timeline, b.timeline, page_call(lambda: a.timeline.diff(b.timeline)))
            root.diffs[(a.number, b.number)] = kept
        return kept[2]


def _step(timeline: Timeline, step: int) -> int:
    if not 0 <= step <= len(timeline):
        raise InspectorError(400, f"no step {step}: the timeline has steps 0 to {len(timeline)}")
    return step
