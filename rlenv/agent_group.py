"""RLAgentGroup: a group of agents of one role, stepped as arrays (a swarm, a crowd, a fleet).

To the tree, the roster, the episode log, snapshots and replays a group is one agent whose
observation and action are arrays stacked over its members; its members come and go through a
mask (docs/several-agents.md, "Swarms"). Godot has no agent group: its *groups*
(``add_to_group``) are tags on nodes, another thing. The capacity is named after Godot's
``MultiMesh.instance_count`` (many instances of one kind, stored as arrays).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import batch_space

from rlenv._group_members import GroupMembers
from rlenv.agent import RLAgent
from rlenv.demonstration_keys import idle_action

__all__ = ["MAX_INSTANCE_COUNT", "RLAgentGroup", "stacked_space"]

MAX_INSTANCE_COUNT = 65_536
"""The most members a group may declare (``instance_count``)."""

_MEMBER_SPACES = (spaces.Box, spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)


def stacked_space(member: spaces.Space, count: int) -> spaces.Space:
    """The space of ``count`` members' values of ``member``, stacked on a first axis.

    A ``Box`` stacks as gymnasium's ``batch_space`` does (``(count, *shape)``), a ``Discrete``
    becomes a ``MultiDiscrete`` of ``count``; a ``MultiDiscrete`` and a ``MultiBinary`` keep
    their kind, with the shape ``(count, *shape)``.

    Raises:
        TypeError: ``member`` is not a Box, Discrete, MultiDiscrete or MultiBinary.
    """
    if isinstance(member, spaces.Box):
        return batch_space(member, count)
    if isinstance(member, spaces.Discrete):
        return spaces.MultiDiscrete(
            np.full(count, member.n), dtype=member.dtype, start=np.full(count, member.start)
        )
    if isinstance(member, spaces.MultiDiscrete):
        shape = (count, *member.nvec.shape)
        return spaces.MultiDiscrete(
            np.broadcast_to(member.nvec, shape).copy(),
            dtype=member.dtype,
            start=np.broadcast_to(member.start, shape).copy(),
        )
    if isinstance(member, spaces.MultiBinary):
        return spaces.MultiBinary((count, *np.atleast_1d(member.n)))
    raise TypeError(f"a group's members have no space of the kind {type(member).__name__}")


class _Buffer:
    """One of a group's arrays: allocated once, written in place, never replaced.

    ``group.rewards += 1.0`` works (numpy adds in place and hands back the same array); any
    other assignment is refused, saying how to write into the array instead.
    """

    def __init__(self, attribute: str, doc: str) -> None:
        self._attribute = attribute
        self.__doc__ = doc

    def __set_name__(self, owner: type, name: str) -> None:
        self._name = name

    def __get__(self, group: Any, owner: type | None = None) -> Any:
        if group is None:
            return self
        return getattr(group, self._attribute)

    def __set__(self, group: Any, value: Any) -> None:
        if value is not getattr(group, self._attribute):
            raise AttributeError(
                f"{type(group).__name__}.{self._name} is allocated once and written in place: "
                f"write into it (self.{self._name}[...] = value), never replace it"
            )


class RLAgentGroup(RLAgent):
    """Override to define a group of agents of one role, handled at once as arrays.

    Set :attr:`instance_count` (the most members), :attr:`member_observation_space` and
    :attr:`member_action_space` (one member's spaces: a ``Box``, ``Discrete``,
    ``MultiDiscrete`` or ``MultiBinary``) as class attributes. rlenv derives
    :attr:`~rlenv.agent.RLAgent.observation_space` and
    :attr:`~rlenv.agent.RLAgent.action_space`, the members' spaces stacked
    (:func:`stacked_space`), and allocates the group's arrays once; they are written in place
    and never replaced:

    - :attr:`observations` ``(N, *obs_shape)``: write them in :meth:`get_data` and return them;
    - :attr:`actions` ``(N, *act_shape)``: the group's action as last applied (rows of members
      not in play hold :meth:`no_action`'s rows); apply it in ``_physics_process``;
    - :attr:`rewards` ``(N,)`` float64: add to them in ``_after_physics_tick`` (summed since
      the last answer);
    - :attr:`terminations`, :attr:`truncations` ``(N,)`` bool: set a member's to end it;
    - :attr:`active` ``(N,)`` bool, read-only: the members in play.

    Members come and go: :meth:`add_member` (a member joins: its first transition has reward 0
    and a ``joined`` row) and :meth:`remove_member`, or a member's ``terminations`` /
    ``truncations`` row set in a hook (it leaves). A member that ends has its final transition
    (its observation row, reward and flags, taken at the end of the tick in which it ended) in
    the answer of that step, then is out of play for the rest of the episode: its rows are
    zeros in the answers, its slot is not used again (member ``i`` is slot ``i``). Its end
    does not cut the step short. The group as one agent ends when no member is left in play
    (terminated, unless every member that left was truncated).

    At each reset every slot is free again; the first :attr:`initial_count` members (all by
    default) start in play, before the environment's reset hooks run; within them (the
    group's :meth:`~rlenv.agent.RLAgent.reset` say) :meth:`remove_member` takes a member out of
    the start (its slot stays free to join later) and :meth:`add_member` puts one in.

    ``decision_period``, ``decision_offset`` and ``act_between_decisions`` apply to the group
    as a whole: its members decide together.

    Attributes:
        instance_count: the declared maximum of members, 1 to :data:`MAX_INSTANCE_COUNT`
            (Godot's ``MultiMesh.instance_count``).
        initial_count: how many members start an episode in play (slots ``0..initial_count-1``);
            ``None``, the default, starts all of them.
        member_observation_space: one member's observation space.
        member_action_space: one member's action space.
    """

    instance_count: ClassVar[int]
    initial_count: ClassVar[int | None] = None
    member_observation_space: ClassVar[spaces.Space]
    member_action_space: ClassVar[spaces.Space]
    _IS_GROUP: ClassVar[bool] = True

    def __init__(self, name: str | None = None) -> None:
        super().__init__(name)
        cls = type(self)
        count = _checked_count(cls)
        for derived in ("observation_space", "action_space"):
            if any(derived in vars(klass) for klass in cls.__mro__[:-1]):
                raise TypeError(
                    f"{cls.__name__} sets {derived}: a group derives it from member_{derived} "
                    "(one member's space), stacked over instance_count"
                )
        member_observation = _member_space(cls, "member_observation_space")
        member_action = _member_space(cls, "member_action_space")
        self.observation_space = stacked_space(member_observation, count)
        self.action_space = stacked_space(member_action, count)
        self._observations = _array(self.observation_space)
        self._actions = _array(self.action_space)
        self._no_action = np.stack([np.asarray(idle_action(member_action))] * count).astype(
            self.action_space.dtype
        )
        self._actions[...] = self._no_action
        self._idle_is_default = cls.no_action is RLAgentGroup.no_action
        self._rewards = np.zeros(count, np.float64)
        self._terminations = np.zeros(count, np.bool_)
        self._truncations = np.zeros(count, np.bool_)
        self._active = np.zeros(count, np.bool_)
        self._active_view = self._active.view()
        self._active_view.flags.writeable = False
        self._members = GroupMembers(self)

    # --- the arrays -------------------------------------------------------------------------

    observations = _Buffer(
        "_observations",
        "``(N, *obs_shape)``: the members' observations, written in place by :meth:`get_data`.",
    )
    actions = _Buffer(
        "_actions", "``(N, *act_shape)``: the group's action as last applied (read it)."
    )
    rewards = _Buffer(
        "_rewards", "``(N,)`` float64: each member's reward since the last answer (add to it)."
    )
    terminations = _Buffer("_terminations", "``(N,)`` bool: set a member's to end it, terminated.")
    truncations = _Buffer("_truncations", "``(N,)`` bool: set a member's to end it, truncated.")

    @property
    def active(self) -> np.ndarray:
        """``(N,)`` bool, read-only: the members in play now."""
        return self._active_view

    # --- members ----------------------------------------------------------------------------

    def add_member(self, index: int | None = None) -> int:
        """A member joins: slot ``index``, or the lowest slot not used in this episode.

        During an episode its first transition is in the next answer, with reward 0 and its
        ``joined`` row set.

        Returns:
            The member's slot.

        Raises:
            ValueError: no slot is free, ``index`` played already in this episode, is out of
                range, or the group has ended (no member left in play).
        """
        return self._members.add(index)

    def remove_member(self, index: int, truncated: bool = False) -> None:
        """Member ``index`` leaves: its episode ends, terminated unless ``truncated``.

        Its final transition is in this step's answer. During a reset's hooks it only takes
        the member out of the start (its slot stays free).

        Raises:
            ValueError: ``index`` is out of range or not in play.
        """
        self._members.remove(index, truncated)

    # --- RLAgent ----------------------------------------------------------------------------

    def set_action(self, action: Any) -> None:
        """Copy the checked group action into :attr:`actions` (members out of play: no action)."""
        actions = self._actions
        np.copyto(actions, action, casting="unsafe")
        members = self._members
        if not members.full:
            idle = self._no_action if self._idle_is_default else self.no_action()
            np.copyto(actions, idle, where=members.idle_rows)

    def no_action(self) -> np.ndarray:
        """The group's idle action: every member's idle action (override for another)."""
        return self._no_action.copy()

    def get_data(self, observation_request: Mapping[str, Any]) -> Any:
        """Write :attr:`observations` in place and return them (override it)."""
        raise NotImplementedError(f"{type(self).__name__} must implement get_data")


def _checked_count(cls: type[RLAgentGroup]) -> int:
    count = getattr(cls, "instance_count", None)
    if type(count) is not int or not 1 <= count <= MAX_INSTANCE_COUNT:
        raise ValueError(
            f"{cls.__name__}.instance_count must be an integer in 1..{MAX_INSTANCE_COUNT} "
            f"(the most members of the group), got {count!r:.40}"
        )
    return count


def _member_space(cls: type[RLAgentGroup], attribute: str) -> spaces.Space:
    space = getattr(cls, attribute, None)
    if not isinstance(space, spaces.Space):
        raise TypeError(f"{cls.__name__} must set {attribute} to a gymnasium space (one member's)")
    if not isinstance(space, _MEMBER_SPACES):
        raise TypeError(
            f"{cls.__name__}.{attribute} is a {type(space).__name__}: a group's members have "
            "Box, Discrete, MultiDiscrete or MultiBinary spaces"
        )
    return space


def _array(space: spaces.Space) -> np.ndarray:
    """A zero array of ``space``'s shape and dtype (clipped into a Box's bounds)."""
    assert space.shape is not None
    return np.zeros(space.shape, space.dtype)
