"""The run's parameters inside a recording: rendered to the node's params-file YAML for the metadata record,
and parsed back to the flat dotted dict / ActuatorParams."""

from __future__ import annotations

from typing import Any, Mapping

from ..params import flatten_tree
from .base import LIBRARY, RecordingError



def plain_value(value: Any) -> Any:
    """YAML-safe Python value (numpy scalars, tuples ...)."""
    if isinstance(value, (bool, str)) or value is None:
        return value
    if isinstance(value, (list, tuple)):
        return [plain_value(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): plain_value(v) for k, v in value.items()}
    if hasattr(value, "item") and callable(value.item):  # numpy scalar
        value = value.item()
    if isinstance(value, (int, float)):
        return value
    return str(value)


def _nest(flat: Mapping[str, Any]) -> dict[str, Any]:
    tree: dict[str, Any] = {}
    for key, value in flat.items():
        node = tree
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ValueError(f"parameter {key!r} conflicts with a parameter named {part!r}")
        node[parts[-1]] = value
    return tree


def render_parameters(parameters: Any) -> tuple[str, dict[str, Any]]:
    """``(yaml_text, flat_dict)`` for an ActuatorParams or a flat (or nested) parameter dict.

    Model keys (``params.SPECS``) are validated and written by :func:`params.dump_yaml` (every model
    parameter, defaults filled in); other keys (``node.*``, ``preset``, ...) are appended under the same
    ``ros__parameters`` mapping. Raises ParameterError naming a bad or unknown model field.
    """
    from .. import params as P

    if isinstance(parameters, P.ActuatorParams):
        return P.dump_yaml(parameters, header=f"parameters recorded by {LIBRARY}"), P.to_flat(parameters)
    if not isinstance(parameters, Mapping):
        raise TypeError(f"parameters: expected ActuatorParams or a dict, got {type(parameters).__name__}")
    flat = flatten_tree(parameters)
    model = {k: v for k, v in flat.items() if k in P.SPECS}
    # None (a ROS parameter that is not set) has no params-file form: such keys are left out
    extra = {k: plain_value(v) for k, v in flat.items() if k not in P.SPECS and v is not None}
    for key in extra:
        if key.split(".")[0] in P.SECTIONS:
            raise P.ParameterError(key, "unknown model parameter")
    params = P.from_flat(model)
    text = P.dump_yaml(params, header=f"parameters recorded by {LIBRARY}") if model else \
        f"{P.YAML_NODE_KEY}:\n  ros__parameters:\n"
    if extra:
        import yaml

        dumped = yaml.safe_dump(_nest(extra), default_flow_style=False, sort_keys=False, allow_unicode=True)
        text += "".join(f"    {line}\n" for line in dumped.splitlines())
    out = P.to_flat(params) if model else {}
    out.update(extra)
    return text, out


def parameters_from_yaml(text: str) -> dict[str, Any]:
    """Flat dotted dict from parameter YAML text (node layout or plain mapping); model values normalised
    like ``params.to_flat`` when they form valid parameters."""
    import yaml

    from .. import params as P

    tree = yaml.safe_load(text) or {}
    if not isinstance(tree, Mapping):
        raise ValueError("parameters YAML is not a mapping")
    if len(tree) == 1:
        (only,) = tree.values()
        if isinstance(only, Mapping) and "ros__parameters" in only:
            tree = only["ros__parameters"] or {}
    flat = flatten_tree(tree)
    model = {k: v for k, v in flat.items() if k in P.SPECS}
    if model:
        flat.update(P.to_flat(P.from_flat(model)))
    return flat


def model_params(text: str):
    from .. import params as P

    flat = parameters_from_yaml(text)
    model = {k: v for k, v in flat.items() if k in P.SPECS}
    if not model:
        raise RecordingError("the recorded parameters contain no model parameter")
    return P.from_flat(model)
