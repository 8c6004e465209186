"""A client's answers: the one awaited among those that arrive, and each checked.

:class:`Answers` is what a :class:`~rlenv_client.base.BaseClient` holds to read its answers. A
client waits for one answer at a time, the answer to the request it sent last
(:attr:`Answers.awaited`): an answer to an earlier request, whose caller gave up on it, is read
when it comes and dropped. Each answer is checked: an error reply is raised as a
:class:`~rlenv.protocol.errors.RemoteError` (a fatal one closes the client), and an answer of
the wrong kind, or one that cannot be unpacked, closes the client and raises
:class:`~rlenv.protocol.errors.ConnectionLost`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any, TypeVar

from rlenv.protocol import BatchResponse, ErrorReply, Reply, Response, StepsResponse
from rlenv.protocol.errors import ConnectionLost, RemoteError
from rlenv.protocol.spaces import Codec

__all__ = ["Answers"]

logger = logging.getLogger("rlenv_client.base")  # where the dropped answers were logged

_Answer = TypeVar("_Answer", BatchResponse, StepsResponse)


class Answers:
    """The answers of the environment at ``address``.

    Args:
        address: where the environment is, for messages.
        receive: waits for the environment's next answer (without ``copy``, a ``steps``
            answer may hold views valid until the next request).
        close: closes the client, when an answer is fatal or breaks the protocol.
    """

    def __init__(
        self, address: str, receive: Callable[[bool], Reply], close: Callable[[], None]
    ) -> None:
        self._address = address
        self._receive = receive
        self._close = close
        self.awaited = 0
        """The id of the request sent last: the answer to wait for."""

    def reply(self, copy: bool = True) -> Reply:
        """The answer to the request sent last; answers to earlier ones are dropped.

        Their callers gave up on them (interrupted while waiting), so they belong to no one;
        an unsolicited error (id ``None``: a timeout, say) is returned as it is.
        """
        while True:
            message = self._receive(copy)
            reply_id = message.id
            if reply_id is None or reply_id >= self.awaited:
                return message
            logger.info(
                "%s: dropped the answer to request %d, whose caller gave up on it",
                self._address,
                reply_id,
            )

    def reply_or_error(self) -> Response | ErrorReply:
        """The answer to the request sent last; an error reply is returned, not raised."""
        message = self.reply()
        if message.__class__ is not ErrorReply:
            return self.response(message)  # type: ignore[arg-type]  # checks it is a Response
        if message.fatal:
            self._close()
        return message

    def of_kind(self, kind: type[_Answer], asked: str, copy: bool = True) -> _Answer:
        """The answer to a batch or steps request, ``kind``; raises a refusal of it whole."""
        message = self.reply(copy)
        if message.__class__ is ErrorReply:
            self.response(message)  # raises
        if message.__class__ is not kind:
            self._close()
            raise ConnectionLost(f"{self._address} answered {asked} with {message!r:.80}")
        return message

    def response(self, message: Response | ErrorReply) -> Response:
        """``message`` as a response; an error reply is raised.

        Raises:
            RemoteError: ``message`` is an error reply (a fatal one closes the client).
            ConnectionLost: ``message`` is another kind of answer.
        """
        if message.__class__ is ErrorReply:
            if message.fatal:
                self._close()
            raise RemoteError(message.code, message.message, message.fatal)
        if message.__class__ is not Response:
            self._close()
            raise ConnectionLost(f"{self._address} answered a request with {message!r:.80}")
        return message

    def part(self, response: Response, part: str) -> Any:
        """The ``part`` observation of ``response`` (a response without it breaks the protocol)."""
        observation = response.observation
        if observation is None or part not in observation:
            self._close()
            raise ConnectionLost(f"{self._address} broke the protocol: no {part!r} observation")
        return observation[part]

    def unpack(self, codec: Codec, packed: Any, writable: bool = True) -> Any:
        """``packed`` unpacked by ``codec`` (what it cannot unpack breaks the protocol)."""
        try:
            return codec.unpack(packed, writable)
        except (KeyError, TypeError, ValueError) as error:
            self._close()
            raise ConnectionLost(f"{self._address} broke the protocol: {error}") from None
