"""Parameter overrides by name, for every node that declares it or for one node.

An override key is either a dotted parameter name (``barrier.alpha1.gain``), applied to every
node that declares it, or ``NODE/NAME`` (``hand_sim_node/model.friction_coefficient``),
applied to that node only: a model mismatch, e.g. a plant whose friction or object mass is
not the controllers' model's. For its node a ``NODE/NAME`` key beats the plain ``NAME``.

:func:`override_errors` says what is wrong with a set of keys; :func:`node_overrides` is the
one place that picks the overrides of one node.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from grasp_safety_filter.io.parameters import suggestion
from grasp_safety_filter.io.schemas.nodes import NODE_SCHEMAS

#: Separates the node from the parameter name in a node-scoped override key.
NODE_SEPARATOR = '/'


def split_override(key: str) -> tuple[str | None, str]:
    """Return ``(node, name)`` of ``NODE/NAME``, ``(None, name)`` of a plain ``NAME``."""
    node, separator, name = key.partition(NODE_SEPARATOR)
    return (node, name) if separator else (None, key)


def override_errors(keys: Iterable[str]) -> list[str]:
    """Return what is wrong with each override key (empty: nothing).

    A plain name must be declared by some node; ``NODE/NAME`` must name a node of
    :data:`NODE_SCHEMAS` that declares ``NAME``. Each message names the key and, where one
    is close, suggests a node or a name (or says which nodes do declare ``NAME``).
    """
    errors = []
    for key in keys:
        node, name = split_override(key)
        if node is None:
            if not any(schema.get(name) for schema in NODE_SCHEMAS.values()):
                known = sorted({n for schema in NODE_SCHEMAS.values() for n in schema.names})
                errors.append(f"override '{key}': no node declares it{suggestion(name, known)}")
        elif node not in NODE_SCHEMAS:
            errors.append(
                f"override '{key}': unknown node '{node}'{suggestion(node, NODE_SCHEMAS)}; "
                f'expected NODE/NAME with NODE one of {sorted(NODE_SCHEMAS)}'
            )
        elif not NODE_SCHEMAS[node].get(name):
            owners = sorted(other for other, schema in NODE_SCHEMAS.items() if schema.get(name))
            declared = f' (declared by {owners})' if owners else ''
            hint = declared or suggestion(name, NODE_SCHEMAS[node].names)
            errors.append(f"override '{key}': node '{node}' does not declare '{name}'{hint}")
    return errors


def node_overrides(overrides: Mapping[str, Any], node: str) -> dict[str, Any]:
    """Return ``{name: value}`` of the overrides that apply to ``node``.

    The plain names ``node`` declares, then its ``NODE/NAME`` keys, which replace them. Keys
    of other nodes and names ``node`` does not declare are left out (check them with
    :func:`override_errors`).
    """
    schema = NODE_SCHEMAS[node]
    plain = {key: value for key, value in overrides.items() if NODE_SEPARATOR not in key}
    scoped = {
        name: value
        for key, value in overrides.items()
        for owner, name in [split_override(key)]
        if owner == node
    }
    return {name: value for name, value in {**plain, **scoped}.items() if schema.get(name)}
