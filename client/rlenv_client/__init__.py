"""rlenv_client: drive rlenv environments over TCP from any trainer.

It imports no physics and no server code: only the shared protocol, spaces and errors.
"""

from rlenv.errors import (
    ConnectionLost as ConnectionLost,
)
from rlenv.errors import (
    ErrorCode as ErrorCode,
)
from rlenv.errors import (
    ProtocolVersionError as ProtocolVersionError,
)
from rlenv.errors import (
    RemoteError as RemoteError,
)
from rlenv.errors import (
    RequestTimeout as RequestTimeout,
)
from rlenv.errors import (
    RlenvError as RlenvError,
)
from rlenv_client.client import Client as Client
from rlenv_client.client import StepResult as StepResult
from rlenv_client.launcher import ServerProcess as ServerProcess
from rlenv_client.launcher import ServerStartError as ServerStartError

__all__ = [
    "Client",
    "ConnectionLost",
    "ErrorCode",
    "ProtocolVersionError",
    "RemoteError",
    "RequestTimeout",
    "RlenvError",
    "ServerProcess",
    "ServerStartError",
    "StepResult",
]
