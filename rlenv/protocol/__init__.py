"""The rlenv wire protocol, sans-IO, shared by the server and the client (like h11).

Three layers, one module each:

- :mod:`~rlenv.protocol.codec`: bytes. Frames (a 4-byte big-endian length, then one msgpack
  map), msgpack with numpy arrays as an ext type;
- :mod:`~rlenv.protocol.messages`: typed messages (:class:`Hello`, :class:`Request`,
  :class:`Response`, :class:`ErrorReply`, :class:`BatchResponse`, :class:`StepsResponse`),
  each with ``to_wire`` / ``from_wire``;
- :mod:`~rlenv.protocol.connection`: the state machine (:class:`Connection`), with its
  transitions in one table.

What a request's parts mean is the server's business (:mod:`rlenv.serving._parts`); how values
of a space travel is :mod:`rlenv.protocol.spaces`'. A client on the server's machine may carry
its steps through shared memory instead (protocol 2.3): :mod:`~rlenv.protocol.shared_memory`
says which requests and answers fit the slots, :mod:`~rlenv.transport.lanes` does the I/O.
``docs/protocol.md`` is the spec for other languages. Importing this package loads neither the
runtime nor pymunk.
"""

from rlenv.protocol.codec import DEFAULT_MAX_FRAME_SIZE as DEFAULT_MAX_FRAME_SIZE
from rlenv.protocol.codec import NDARRAY_EXT as NDARRAY_EXT
from rlenv.protocol.codec import frame as frame
from rlenv.protocol.codec import pack as pack
from rlenv.protocol.codec import unpack as unpack
from rlenv.protocol.connection import CONNECTION_CLOSED as CONNECTION_CLOSED
from rlenv.protocol.connection import NEED_DATA as NEED_DATA
from rlenv.protocol.connection import Connection as Connection
from rlenv.protocol.connection import Role as Role
from rlenv.protocol.connection import State as State
from rlenv.protocol.messages import PROTOCOL_VERSION as PROTOCOL_VERSION
from rlenv.protocol.messages import BatchResponse as BatchResponse
from rlenv.protocol.messages import ErrorReply as ErrorReply
from rlenv.protocol.messages import GroupSpec as GroupSpec
from rlenv.protocol.messages import Hello as Hello
from rlenv.protocol.messages import Message as Message
from rlenv.protocol.messages import Reply as Reply
from rlenv.protocol.messages import Request as Request
from rlenv.protocol.messages import Response as Response
from rlenv.protocol.messages import StepsResponse as StepsResponse

__all__ = [
    "CONNECTION_CLOSED",
    "DEFAULT_MAX_FRAME_SIZE",
    "NDARRAY_EXT",
    "NEED_DATA",
    "PROTOCOL_VERSION",
    "BatchResponse",
    "Connection",
    "ErrorReply",
    "GroupSpec",
    "Hello",
    "Message",
    "Reply",
    "Request",
    "Response",
    "Role",
    "State",
    "StepsResponse",
    "frame",
    "pack",
    "unpack",
]
