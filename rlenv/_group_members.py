"""A group's members through an episode: who plays, who joined, who left, what each earned.

The bookkeeping of :class:`~rlenv.agent_group.RLAgentGroup`, vectorised (no loop over
members): the server's roster runs it at a reset (:meth:`GroupMembers.begin`,
:meth:`GroupMembers.start`), at the end of each tick (:meth:`GroupMembers.ticked`) and at each
answer (:meth:`GroupMembers.outcome`, :meth:`GroupMembers.observed`); the group's
``add_member`` and ``remove_member`` come here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from rlenv.agent_group import RLAgentGroup

__all__ = ["GroupMembers"]


class GroupMembers:
    """The members of a group through an episode: who plays, who joined and who left.

    What the server's roster asks of a group (``begin``, ``start``, ``ticked``, ``outcome``,
    ``observed``); the group's methods add and remove members through it.
    """

    __slots__ = (
        "_any_ended",
        "_any_joined",
        "_any_pending",
        "_ended",
        "_final_observations",
        "_final_rewards",
        "_joined",
        "_open",
        "_pending",
        "_rows",
        "_scratch",
        "_end_flags",
        "_used",
        "any_terminated",
        "full",
        "group",
        "idle_rows",
    )

    def __init__(self, group: RLAgentGroup) -> None:
        count = group.instance_count
        self.group = group
        self._used = np.zeros(count, np.bool_)  # slots played in this episode
        self._ended = np.zeros(count, np.bool_)  # ended since the last answer (final owed)
        self._joined = np.zeros(count, np.bool_)  # joined since the last answer
        self._pending = np.zeros(count, np.bool_)  # ended; final observation not taken yet
        self._final_rewards = np.zeros(count, np.float64)
        self._final_observations = np.zeros_like(group._observations)
        self._rows = np.zeros_like(group._observations)  # an answer's masked observation
        self._scratch = np.zeros(count, np.bool_)
        self._end_flags = (np.zeros(count, np.bool_), np.zeros(count, np.bool_))
        self.idle_rows = np.ones(count, np.bool_)  # rows of members not in play (broadcast)
        self.idle_rows = self.idle_rows.reshape((count,) + (1,) * (group._actions.ndim - 1))
        self._open = False  # an episode runs (after the reset's hooks)
        self._any_ended = self._any_joined = False
        self.full = False  # every member in play, none ended: answers need no mask
        self.any_terminated = False

    # --- the roster's ---------------------------------------------------------------------

    def begin(self) -> None:
        """A reset begins: every slot free, the first ``initial_count`` members in play."""
        group = self.group
        count = group.instance_count
        initial = group.initial_count
        start = count if initial is None else initial
        if type(start) is not int or not 0 <= start <= count:
            raise RuntimeError(
                f"{type(group).__name__}.initial_count must be None or an integer in "
                f"0..{count} (its instance_count), got {initial!r:.40}"
            )
        active = group._active
        active[:] = False
        active[:start] = True
        self._used[:] = active
        for array in (group._terminations, group._truncations, self._ended, self._joined):
            array[:] = False
        self._pending[:] = False
        self._any_pending = False
        for flags in self._end_flags:
            flags[:] = False
        group._rewards[:] = 0.0
        group.reward = 0.0
        group.terminated = group.truncated = False
        self._open = self._any_ended = self._any_joined = self.any_terminated = False
        self._update()

    def start(self) -> None:
        """The reset's hooks ran: the members in play start the episode."""
        self._open = True
        group = self.group
        group._rewards[:] = 0.0
        group._terminations[:] = group._truncations[:] = False
        self._update()

    def ticked(self) -> None:
        """The end of a tick, after the hooks: members whose flags were set leave now.

        Their final observation rows are taken now (one :meth:`get_data` of the group).
        """
        group = self.group
        ending = self._scratch
        np.logical_or(group._terminations, group._truncations, out=ending)
        np.logical_and(ending, group._active, out=ending)
        if np.count_nonzero(ending):
            self._end(ending, group._terminations[ending])
        if self._any_pending:
            self._take_finals()

    def clear(self) -> None:
        """Forget what the members earned and who came and left since the last answer."""
        self.group._rewards.fill(0.0)
        if self._any_ended or self._any_joined:
            self._ended.fill(False)
            self._pending.fill(False)  # ended outside a tick: the answer observed them
            self._final_rewards.fill(0.0)
            self._joined.fill(False)
            self._any_ended = self._any_joined = self._any_pending = False
            self._update()

    def outcome(self, reports: bool) -> tuple[dict[str, np.ndarray], float]:
        """An answer's outcome of the group, its arrays, and their total reward.

        Only an answer that ``reports`` (to the controller) tells rewards; the roster clears
        them (:meth:`clear`).
        """
        group = self.group
        active = group._active
        if self._any_ended:
            ended = self._ended
            reward = np.where(ended, self._final_rewards, group._rewards)
            terminated, truncated = (np.logical_and(ended, flags) for flags in self._end_flags)
            reported = active | ended
            reward[~reported] = 0.0
        else:
            reward = np.where(active, group._rewards, 0.0)
            terminated = np.zeros(active.shape, np.bool_)
            truncated = terminated.copy()
            reported = active.copy()
        joined = self._joined.copy()
        if not reports:
            reward[:] = 0.0
        elif self._any_joined:
            reward[joined] = 0.0
        outcome = {
            "reward": reward,
            "terminated": terminated,
            "truncated": truncated,
            "active": reported,
            "joined": joined,
        }
        return outcome, float(reward.sum())

    def observed(self, data: Any) -> Any:
        """What an answer sends of ``data`` (the group's ``get_data``): rows not reported zero.

        Members that ended since the last answer send their final rows.
        """
        if self.full:
            return data
        rows, group = self._rows, self.group
        try:
            np.copyto(rows, data, casting="same_kind")
        except (TypeError, ValueError):  # not of the space: its codec says how, precisely
            return data
        live = group._active | self._pending if self._any_pending else group._active
        rows[~live] = 0
        if self._any_ended:
            taken = self._ended & ~self._pending
            rows[taken] = self._final_observations[taken]
        return rows

    # --- the group's ------------------------------------------------------------------------

    def add(self, index: int | None) -> int:
        group = self.group
        name = group.name
        if self._open and (group.terminated or group.truncated):
            raise ValueError(
                f"group {name} has ended in this episode (no member was left in play): no "
                "member joins it until the next reset"
            )
        if index is None:
            free = np.flatnonzero(~self._used)
            if not free.size:
                raise ValueError(
                    f"group {name} has no free member slot: its instance_count of "
                    f"{group.instance_count} are all used in this episode"
                )
            index = int(free[0])
        else:
            index = self._slot(index)
            if self._used[index]:
                raise ValueError(f"member {index} of group {name} already played in this episode")
        self._used[index] = group._active[index] = True
        group._rewards[index] = 0.0
        group._terminations[index] = group._truncations[index] = False
        if self._open:
            self._joined[index] = self._any_joined = True
        self._update()
        return index

    def remove(self, index: int, truncated: bool) -> None:
        group = self.group
        index = self._slot(index)
        if not group._active[index]:
            raise ValueError(f"member {index} of group {group.name} is not in play")
        if not self._open:  # the reset's hooks: out of the start, its slot free
            group._active[index] = self._used[index] = False
            self._update()
            return
        group._terminations[index] = not truncated
        group._truncations[index] = truncated
        one = np.zeros(group.instance_count, np.bool_)
        one[index] = True
        self._end(one, np.array([not truncated]))

    def _slot(self, index: Any) -> int:
        count = self.group.instance_count
        if not isinstance(index, (int, np.integer)) or isinstance(index, bool):
            raise ValueError(f"a member is an int slot in 0..{count - 1}, got {index!r:.40}")
        if not 0 <= index < count:
            raise ValueError(
                f"member {index} is out of range: group {self.group.name} has "
                f"slots 0..{count - 1} (its instance_count)"
            )
        return int(index)

    def _end(self, ending: np.ndarray, terminated: np.ndarray) -> None:
        """The members ``ending`` leave (``terminated``: how each, in their order)."""
        group = self.group
        group._active[ending] = False
        self._ended |= ending
        self._pending |= ending
        self._any_pending = True
        self._final_rewards[ending] = group._rewards[ending]
        ended_terminated, ended_truncated = self._end_flags
        ended_terminated[ending] = terminated
        ended_truncated[ending] = ~terminated
        self._any_ended = True
        self.any_terminated = self.any_terminated or bool(terminated.any())
        self._update()
        if not np.count_nonzero(group._active):
            group.terminated = self.any_terminated
            group.truncated = not self.any_terminated

    def _take_finals(self) -> None:
        pending = self._pending
        data = np.asarray(self.group.get_data({}))
        self._final_observations[pending] = data[pending]
        pending[:] = False
        self._any_pending = False

    def _update(self) -> None:
        active = self.group._active
        self.full = np.count_nonzero(active) == active.size and not self._any_ended
        self.idle_rows.reshape(-1)[:] = ~active
