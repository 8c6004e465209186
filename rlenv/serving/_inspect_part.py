"""The ``inspect`` part: an inspector reads the tree, or changes a property or a setting.

A record of :data:`rlenv.serving._parts.PARTS`; the operations themselves are
:mod:`rlenv.serving._inspector`'s.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlenv.serving import _inspector as inspector
from rlenv.serving._instance import Answer, Instance, Plan
from rlenv.serving._part_record import Part

__all__ = ["Inspect"]


class Inspect(Part):
    """An inspector's request (:mod:`rlenv.serving._inspector`): read, or change a property.

    It reads the tree, a node, a property or the statistics, or changes a property or a
    setting.

    It never takes control: a change from an observer applies between two of the controller's
    requests, at a tick boundary, and is logged as the controller's own would be.
    """

    name = "inspect"
    alone = True

    def check(self, instance: Instance, parts: Mapping[str, Any], fresh: bool, where: str) -> Any:
        operation, arguments = inspector.check_inspect(parts["inspect"])
        environment = instance.environment
        if operation == "get":
            inspector.get_property(environment, arguments["path"], arguments["property"])
        elif operation == "node":
            inspector.node_at(environment, arguments["path"])
        elif operation == "set":
            inspector.set_property(
                environment,
                arguments["path"],
                arguments["property"],
                arguments["value"],
                dry_run=True,
            )
        elif operation == "configure":
            instance.settings.check(arguments)
        return operation, arguments

    def apply(self, instance: Instance, value: Any, request: Plan) -> None:
        operation, arguments = value
        environment = instance.environment
        answer: Answer = instance.answer  # type: ignore[assignment]
        if operation == "tree":
            answer.info = {"tree": inspector.tree(environment)}
        elif operation == "node":
            answer.info = {"node": inspector.node_of(environment, arguments["path"])}
        elif operation == "get":
            answer.info = {
                "value": inspector.get_property(
                    environment, arguments["path"], arguments["property"]
                )
            }
        elif operation == "set":
            instance.set_property(arguments["path"], arguments["property"], arguments["value"])
        elif operation == "configure":
            instance.settings.configure(arguments)
        else:
            answer.info = {"stats": instance.stats.since(arguments.get("since", 0))}
