"""Answers: the answer to the request an instance serves, and what it says.

An :class:`Answer` gathers what the request's parts and hooks add while it is served;
:class:`Answering` turns it into the :class:`~rlenv.protocol.Response`: what was observed, the
flags, the rewards and ticks since the previous answer (the episode's report), and ``info``.
"""

from __future__ import annotations

from typing import Any

from rlenv.protocol import Response
from rlenv.serving._episode import EpisodeRun
from rlenv.serving._observing import check_text_keys
from rlenv.serving._players import Players

__all__ = ["Answer", "Answering"]


class Answer:
    """The answer to the request being served, as its parts and hooks build it."""

    __slots__ = ("acted", "config_before", "info", "reply", "reply_id", "reports")

    def __init__(self, reply_id: int, reports: bool) -> None:
        self.reply_id = reply_id
        self.reports = reports  # it goes to the controller: rewards and ticks are its
        self.info: dict[str, Any] | None = None  # entries beside the environment's own
        self.acted = False
        self.config_before: dict[str, dict[str, Any]] | None = None  # to undo on failure
        self.reply: Response | None = None


class Answering:
    """What an instance's answers say, from its episode and who plays its agents.

    Args:
        episode: the instance's episode run, which reports the rewards, flags and ticks.
        players: who acts for agents beside the controller (the claims an answer lists).
    """

    __slots__ = ("_episode", "_players")

    def __init__(self, episode: EpisodeRun, players: Players) -> None:
        self._episode = episode
        self._players = players

    def response(self, answer: Answer, observation: dict[str, Any] | None) -> Response:
        """The answer: what was observed, the flags, and the rewards and ticks since the last."""
        reward, terminated, truncated, frames, outcomes = self._episode.report(
            answer.reports, answer.acted
        )
        return Response(
            answer.reply_id,
            observation,
            reward,
            terminated,
            truncated,
            self.info(answer.acted, answer.info),
            frames,
            outcomes,
        )

    def info(self, acted: bool, extra: dict[str, Any] | None) -> dict[str, Any]:
        """An answer's ``info``: ``_get_info()`` while an episode exists, real time's, ``extra``.

        While observers claim agents (:mod:`rlenv.serving._claims`), ``"claimed"`` lists them.
        """
        info = self._episode.info(acted)
        if extra:
            check_text_keys(extra, "the answer holds")
            info = {**info, **extra}
        if self._players.claims is not None:
            info = {**info, "claimed": self._players.claimed(self._episode.roster.agents)}
        return info
