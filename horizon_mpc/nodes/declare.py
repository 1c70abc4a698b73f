"""Declaring the nodes' parameters: descriptions, ranges, read-only flags, and an integer
accepted where a float is declared (at start-up and in a live set)."""

from __future__ import annotations

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

__all__ = ["accept_integers_for_floats", "declare", "float_range", "int_range",
           "parameter_overrides"]


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
    types them as integers, and the declaration would otherwise fail on the type (in a live
    set: :func:`accept_integers_for_floats`).
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
    if given is not None and not isinstance(default, Parameter.Type):
        # a weight list written without dots too (-p "w_base_linear_velocity:=[1,2,3]")
        overrides[name] = _as_float(given, Parameter.Type.from_parameter_value(default))
    node.declare_parameter(name, default, desc)


def _as_float(param: Parameter, declared: Parameter.Type) -> Parameter:
    """``param`` as a float (list) when it is an integer (list) and ``declared`` is a float
    (list) type; else unchanged."""
    if param.type_ == Parameter.Type.INTEGER and declared == Parameter.Type.DOUBLE:
        return Parameter(param.name, Parameter.Type.DOUBLE, float(param.value))
    if (param.type_ == Parameter.Type.INTEGER_ARRAY
            and declared == Parameter.Type.DOUBLE_ARRAY):
        return Parameter(param.name, Parameter.Type.DOUBLE_ARRAY,
                         [float(x) for x in param.value])
    return param


def accept_integers_for_floats(node: Node) -> None:
    """Let a live set give an integer to a float parameter and an integer list to a
    float-list one (``ros2 param set /mpc max_vx 1``: the CLI types ``1`` as an integer,
    which rclpy refuses on a float parameter); other types still fail on the type, and an
    undeclared name gets rclpy's own refusal."""
    node.add_pre_set_parameters_callback(
        lambda params: [_as_float(p, node.get_parameter(p.name).type_)
                        if node.has_parameter(p.name) else p for p in params])
