"""LevelWorld: a world whose levels come from the seed or as data (``rlenv.LevelWorld``).

What a world with levels needs for the curriculum features (prioritized level replay, ACCEL;
see docs/procedural.md, "Levels as reset options", and docs/curriculum.md): a reset plays the
level given as ``options["level"]`` (the data of a :class:`~rlenv.PackedScene`, checked
against :attr:`LevelWorld.level_classes`) or builds one from the episode's generator;
``client.get_property("World", "level")`` reads the episode's level as data, packed once; a
given level is built and checked while the server checks the reset's request
(:meth:`LevelWorld.check_options`, :meth:`LevelWorld.check_level`), so that one refused leaves
the episode under way alone; :attr:`LevelWorld.level_id` is its fingerprint, computed once;
and ``client.edit_level(level, seed, n_edits)`` edits a level given as data or as an int seed
(ACCEL). Plinko's and Maze's worlds derive from it. A subclass implements what is its own:
:meth:`~LevelWorld.build_level`, :meth:`~LevelWorld.edit_level_data`, and the draws a reset
makes before the level (:meth:`~LevelWorld.draw_before_level`, none by default).
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from typing import Any, ClassVar

import msgpack
import numpy as np
from gymnasium.utils import seeding

from rlenv.node import Node
from rlenv.scene2d.node2d import Node2D
from rlenv.scene2d.packed_scene import PackedScene
from rlenv.world import RLEnvWorld

__all__ = ["LevelWorld"]


class LevelWorld(RLEnvWorld):
    """A world that plays one level per episode: given as data, or built from the seed.

    Subclasses set :attr:`level_classes`, implement :meth:`build_level` and
    :meth:`edit_level_data`, call :meth:`new_level` in their ``reset`` and set
    :attr:`level_node` to the level they play.
    """

    exported = ("level",)
    level_classes: ClassVar[tuple[type[Node], ...]] = ()
    """The classes a level's data may name besides rlenv's own."""

    def __init__(self, name: str = "World") -> None:
        super().__init__(name)
        self._level_node: Node2D | None = None
        self._level_data: dict[str, Any] | None = None
        self._level_id = ""
        self._checked: tuple[Any, Node2D] | None = None  # a given level, built by its check

    def build_level(self, rng: np.random.Generator) -> Node2D:
        """Override: a new level, every random choice from ``rng`` (at the world's settings).

        A reset calls it with the episode's generator after :meth:`draw_before_level`.
        """
        raise NotImplementedError(f"{type(self).__name__} has no build_level")

    def edit_level_data(
        self, data: dict[str, Any], rng: np.random.Generator, n_edits: int
    ) -> dict[str, Any]:
        """Override: ``n_edits`` random edits of a level's data (checked already; not changed).

        A world whose module has such a function may set ``edit_level_data =
        staticmethod(edit_level)``.

        Raises:
            ValueError: the data is not a level this world can edit.
        """
        raise NotImplementedError(f"{type(self).__name__} has no edit_level_data")

    def draw_before_level(self, rng: np.random.Generator) -> Any:
        """Override to draw from ``rng`` what a reset draws before the level; ``None`` here.

        A reset plays its result (:meth:`new_level` returns it), and the level of an int seed
        in :meth:`_edit_level` is built after the same draws, as a reset with that seed does.
        """
        return None

    def check_level(self, level: Node2D) -> None:
        """Override to refuse a given level that its data's checks let through; nothing here.

        Raises:
            ValueError: ``level`` (built from a client's data, not in the tree) is not a level
                this world plays.
        """

    def check_options(self, options: Mapping[str, Any]) -> None:
        """Build ``options["level"]`` and :meth:`check_level` it, before anything changes.

        The server calls this while it checks the request, so that a level refused here
        leaves the episode under way alone; the level built is the one :meth:`new_level`
        plays.

        Raises:
            PackedSceneError: ``options["level"]`` is not a level this world may build.
            ValueError: :meth:`check_level` refused it.
        """
        self._checked = None
        given = options.get("level")
        if given is not None:
            self._checked = (given, self._given_level(given))

    def _given_level(self, given: Any) -> Node2D:
        level = PackedScene.from_data(given, allowed=self.level_classes).instantiate()
        if not isinstance(level, Node2D):
            raise ValueError(f"a level's root is a Node2D, not a {type(level).__name__}")
        self.check_level(level)
        return level

    def new_level(self, options: Mapping[str, Any]) -> tuple[Any, Node2D]:
        """This episode's draws before the level, then its level: the given one or a new one.

        ``options["level"]`` is checked before anything is drawn (the server checked and built
        it already, :meth:`check_options`); without it, the level is :meth:`build_level`'s
        from the episode's generator.

        Returns:
            What :meth:`draw_before_level` drew, and the level (not yet in the tree).

        Raises:
            PackedSceneError: ``options["level"]`` is not a level this world may build.
            ValueError: :meth:`check_level` refused it.
        """
        given = options.get("level")
        checked, self._checked = self._checked, None
        level = None
        if given is not None:
            level = (
                checked[1]
                if checked is not None and checked[0] is given
                else self._given_level(given)
            )
        rng = self.np_random
        drawn = self.draw_before_level(rng)
        return drawn, level if level is not None else self.build_level(rng)

    @property
    def level_node(self) -> Node2D | None:
        """This episode's level; setting it forgets the last one's data and fingerprint."""
        return self._level_node

    @level_node.setter
    def level_node(self, level: Node2D | None) -> None:
        self._level_node = level
        self._level_data = None
        self._level_id = ""

    @property
    def level(self) -> dict[str, Any] | None:
        """This episode's level as data (a PackedScene's); ``None`` before the first reset.

        Play it again with ``reset(options={"level": level})``.
        """
        if self._level_node is None:
            return None
        if self._level_data is None:
            self._level_data = PackedScene.pack(self._level_node).to_data()
        return self._level_data

    @property
    def level_id(self) -> str:
        """The level's fingerprint: sha256 of its data's msgpack, 16 hex digits; computed once.

        ``""`` before the first reset.
        """
        if not self._level_id and self._level_node is not None:
            self._level_id = hashlib.sha256(msgpack.packb(self.level)).hexdigest()[:16]
        return self._level_id

    def _edit_level(self, level: Any, rng: np.random.Generator, n_edits: int) -> Any:
        """``n_edits`` edits of ``level`` (:meth:`edit_level_data`), checked before and after.

        An int level is a seed: the level a reset with that seed builds at the world's
        settings (after the same :meth:`draw_before_level`), its data edited. Nothing of the
        world changes.

        Raises:
            ValueError: ``level`` is neither an int seed >= 0 nor this world's level's data.
        """
        if type(level) is int:
            if level < 0:
                raise ValueError(f"a seed must be >= 0, got {level}")
            rng_of_seed, _ = seeding.np_random(level)
            self.draw_before_level(rng_of_seed)
            data = PackedScene.pack(self.build_level(rng_of_seed)).to_data()
        else:
            data = PackedScene.from_data(level, allowed=self.level_classes).to_data()
        edited = self.edit_level_data(data, rng, n_edits)
        return PackedScene.from_data(edited, allowed=self.level_classes).to_data()
