"""Declaring the nodes' parameters: descriptions, ranges, read-only flags, and an integer
accepted where a float is declared."""

from __future__ import annotations

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

__all__ = ["declare", "float_range", "int_range", "parameter_overrides"]


def parameter_overrides(node: Node) -> dict[str, Parameter]:
    """The start-up values given for ``node`` (``-p``, params-file sections matching it,
    code's ``parameter_overrides``), as rcl resolved them: rclpy's own dict, in place
    (rclpy keeps it in a private attribute; empty if a version lacks it)."""
    overrides = getattr(node, "_parameter_overrides", None)
    return overrides if isinstance(overrides, dict) else {}


def float_range(lo: float, hi: float) -> list[FloatingPointRange]:
    """The descriptor range ``[lo, hi]`` of a float parameter (any step)."""
    return [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]


def int_range(lo: int, hi: int) -> list[IntegerRange]:
    """The descriptor range ``[lo, hi]`` of an integer parameter (step 1)."""
    return [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]


def declare(node: Node, name: str, default: object, description: str,
            rng: list[FloatingPointRange] | None = None,
            irng: list[IntegerRange] | None = None, read_only: bool = False) -> None:
    """Declare ``name`` with its description, range and read-only flag.

    A float parameter given an integer at start-up (``-p control_rate:=50``, a YAML ``50``)
    takes it as that float, and a float-list parameter an integer list (``[1, 2, 3]``): rcl
    types them as integers, and the declaration would otherwise fail on the type. (Live
    ``ros2 param set`` keeps rclpy's strict typing.)
    """
    desc = ParameterDescriptor(description=description, read_only=read_only)
    if rng:
        desc.floating_point_range = rng
    if irng:
        desc.integer_range = irng
    overrides = parameter_overrides(node)
    given = overrides.get(name)
    if given is not None and given.type_ == Parameter.Type.NOT_SET:
        # rcl reads '-p name:=[]' (an empty list) as no value: the declaration then left
        # the parameter uninitialised, and reading it failed with rclpy's exception
        wanted = (f"it takes a {default.name.lower().replace('_', ' ')}"
                  if isinstance(default, Parameter.Type) else f"its default is {default!r}")
        raise ValueError(f"parameter {name!r} was given no value (an empty list?); {wanted}")
    if (isinstance(default, float) and given is not None
            and given.type_ == Parameter.Type.INTEGER):
        overrides[name] = Parameter(name, value=float(given.value))
    elif (isinstance(default, list) and default and isinstance(default[0], float)
          and given is not None and given.type_ == Parameter.Type.INTEGER_ARRAY):
        # a weight list written without dots (-p "w_base_linear_velocity:=[1,2,3]")
        overrides[name] = Parameter(name, value=[float(x) for x in given.value])
    node.declare_parameter(name, default, desc)
