"""rlenv_client: drive rlenv environments from any trainer.

- :class:`Client`: one environment server over TCP; :class:`LocalClient`: the same API with the
  environment inside this process.
- :class:`RemoteEnv` (a ``gymnasium.Env``) and :class:`RemoteVectorEnv` (a
  ``gymnasium.vector.VectorEnv``); importing this package registers the example ids, e.g.
  ``gymnasium.make("rlenv/CartPole-v0")``.
- :class:`ServerProcess`: a server subprocess that leaves nothing behind.

It imports no physics, no server code (only the shared protocol, spaces and errors, and the
transport) unless an environment is run in process, and none of the tools (``rlenv_tools``:
the inspector, timelines, compliance, benchmarks, datasets, policies) unless asked for one.
"""

from rlenv import __version__ as __version__
from rlenv.protocol.errors import ConnectionLost as ConnectionLost
from rlenv.protocol.errors import ErrorCode as ErrorCode
from rlenv.protocol.errors import ProtocolVersionError as ProtocolVersionError
from rlenv.protocol.errors import RemoteError as RemoteError
from rlenv.protocol.errors import RequestTimeout as RequestTimeout
from rlenv.protocol.errors import RlenvError as RlenvError
from rlenv.protocol.messages import GroupSpec as GroupSpec
from rlenv_client.base import BaseClient as BaseClient
from rlenv_client.base import StepResult as StepResult
from rlenv_client.client import Client as Client
from rlenv_client.env import RemoteEnv as RemoteEnv
from rlenv_client.launcher import ServerProcess as ServerProcess
from rlenv_client.launcher import ServerStartError as ServerStartError
from rlenv_client.local import LocalClient as LocalClient
from rlenv_client.registration import register_environments
from rlenv_client.vector import RemoteVectorEnv as RemoteVectorEnv

__all__ = [
    "BaseClient",
    "Client",
    "ConnectionLost",
    "ErrorCode",
    "GroupSpec",
    "LocalClient",
    "ProtocolVersionError",
    "RemoteEnv",
    "RemoteError",
    "RemoteVectorEnv",
    "RequestTimeout",
    "RlenvError",
    "ServerProcess",
    "ServerStartError",
    "StepResult",
]

register_environments()
