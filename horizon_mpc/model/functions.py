"""The CasADi Functions a :class:`~horizon_mpc.model.RobotModel` offers (mixin).

Each method builds its Function once from the model's shared SX symbols and caches it per
(kind, frames, reference frame); later calls return the cached object.
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as cs

from horizon_mpc.codegen import function_name
from horizon_mpc.model import derivatives, dynamics, kinematics, liegroup

__all__ = ["SymbolicFunctions"]

DEFAULT_REF = "LOCAL_WORLD_ALIGNED"


def _c(text: str) -> str:
    return function_name(text)


class SymbolicFunctions:
    """Function factories; relies on the attributes and helpers set by ``RobotModel``."""

    # ------------------------------------------------------------------ kinematics
    def fk(self, frame: str) -> cs.Function:
        """Forward kinematics of ``frame``: ``q (nq) -> pos (3), rot (3x3)`` in world."""
        fr = self._frame(frame)

        def build() -> cs.Function:
            o_f = kinematics.frame_placement(self._kinematics("none"), fr)
            return cs.Function(f"fk_{_c(frame)}", [self._q], [o_f.p, o_f.R], ["q"], ["pos", "rot"])

        return self._cached(("fk", frame), build)

    def frame_velocity(self, frame: str, ref: str = DEFAULT_REF) -> cs.Function:
        """Frame velocity: ``q (nq), v (nv) -> lin (3), ang (3)`` expressed in ``ref``.

        ``ref``: ``LOCAL``, ``WORLD`` or ``LOCAL_WORLD_ALIGNED`` (default, world axes at the
        frame origin).
        """
        fr, ref = self._frame(frame), self._ref(ref)

        def build() -> cs.Function:
            lin, ang = kinematics.frame_velocity(self._kinematics("sym"), fr, ref)
            return cs.Function(
                f"vel_{_c(frame)}_{ref}", [self._q, self._v], [lin, ang], ["q", "v"], ["lin", "ang"]
            )

        return self._cached(("vel", frame, ref), build)

    def frame_acceleration(self, frame: str, ref: str = DEFAULT_REF) -> cs.Function:
        """Classical frame acceleration: ``q, v, a (nv) -> lin (3), ang (3)`` in ``ref``."""
        fr, ref = self._frame(frame), self._ref(ref)

        def build() -> cs.Function:
            lin, ang = kinematics.frame_acceleration(self._kinematics("sym", "sym"), fr, ref)
            return cs.Function(
                f"acc_{_c(frame)}_{ref}",
                [self._q, self._v, self._a],
                [lin, ang],
                ["q", "v", "a"],
                ["lin", "ang"],
            )

        return self._cached(("acc", frame, ref), build)

    def jacobian(self, frame: str, ref: str = DEFAULT_REF) -> cs.Function:
        """Frame Jacobian: ``q (nq) -> J (6 x nv)``, rows (lin, ang), ``J v`` = velocity."""
        fr, ref = self._frame(frame), self._ref(ref)

        def build() -> cs.Function:
            jac = kinematics.frame_jacobian(self._kinematics("none"), fr, ref, self.nv)
            return cs.Function(f"jac_{_c(frame)}_{ref}", [self._q], [jac], ["q"], ["J"])

        return self._cached(("jac", frame, ref), build)

    # ------------------------------------------------------------------ dynamics
    def _id_expr(
        self, contacts: tuple[str, ...], f: cs.SX, vel: str = "sym", acc: str = "sym"
    ) -> cs.SX:
        kin = self._kinematics(vel, acc)
        fext = dynamics.contact_wrenches(kin, [self._frame(c) for c in contacts], f)
        return dynamics.rnea(self._specs, kin, self._gravity, self.nv, fext)

    def inverse_dynamics(self, contacts: Sequence[str] | None = None) -> cs.Function:
        """Inverse dynamics with point contacts: ``q, v, a, f (3 nc) -> tau (nv)``.

        ``tau = M(q) a + b(q, v) - sum_c J_c(q)^T f_c``, ``J_c`` the linear
        LOCAL_WORLD_ALIGNED Jacobian of contact frame c and ``f_c`` its force in world axes.
        For a floating base ``tau[:6]`` is the (ideally zero) base wrench in the base frame.
        """
        names = self._contacts(contacts)

        def build() -> cs.Function:
            f = cs.SX.sym("f", 3 * len(names))
            tau = self._id_expr(names, f)
            return cs.Function(
                "inverse_dynamics",
                [self._q, self._v, self._a, f],
                [tau],
                ["q", "v", "a", "f"],
                ["tau"],
            )

        return self._cached(("id", names), build)

    def inverse_dynamics_derivatives(self, contacts: Sequence[str] | None = None) -> cs.Function:
        """ID and its Jacobians: ``q, v, a, f -> tau, dtau_dq, dtau_dv, dtau_da, dtau_df``.

        ``dtau_dq`` (nv x nv) is taken on the tangent space:
        ``d/d dq ID(integrate(q, dq), v, a, f)`` at ``dq = 0`` (as Pinocchio's
        ``computeRNEADerivatives``). ``dtau_da`` is the mass matrix, ``dtau_df`` (nv x 3 nc)
        is ``-J_c^T``. Built analytically (see :mod:`horizon_mpc.model.derivatives`), about
        two thirds of the operations of CasADi's AD through the recursion.
        """
        names = self._contacts(contacts)

        def build() -> cs.Function:
            f = cs.SX.sym("f", 3 * len(names))
            frames = [self._frame(c) for c in names]
            outs = derivatives.inverse_dynamics_derivatives(
                self._specs,
                self._kinematics("none"),
                self._v,
                self._a,
                self._gravity,
                self.nv,
                frames,
                f,
            )
            # Common-subexpression elimination: ~10% fewer operations in the compiled code.
            return cs.Function(
                "inverse_dynamics_derivatives",
                [self._q, self._v, self._a, f],
                cs.cse(list(outs)),
                ["q", "v", "a", "f"],
                ["tau", "dtau_dq", "dtau_dv", "dtau_da", "dtau_df"],
            )

        return self._cached(("id_derivatives", names), build)

    def forward_dynamics(self, contacts: Sequence[str] | None = None) -> cs.Function:
        """Forward dynamics (ABA) with point contacts: ``q, v, tau (nv), f (3 nc) -> a (nv)``.

        Inverse of :meth:`inverse_dynamics` in ``a`` (same contact convention).
        """
        names = self._contacts(contacts)

        def build() -> cs.Function:
            f = cs.SX.sym("f", 3 * len(names))
            tau = cs.SX.sym("tau", self.nv)
            kin = self._kinematics("sym")
            fext = dynamics.contact_wrenches(kin, [self._frame(c) for c in names], f)
            acc = dynamics.aba(self._specs, kin, tau, self._gravity, self.nv, fext)
            return cs.Function(
                "forward_dynamics", [self._q, self._v, tau, f], [acc], ["q", "v", "tau", "f"], ["a"]
            )

        return self._cached(("fd", names), build)

    def mass_matrix(self) -> cs.Function:
        """Joint-space inertia matrix (CRBA): ``q -> M (nv x nv)``, symmetric."""

        def build() -> cs.Function:
            mass = dynamics.crba(self._specs, self._kinematics("none"), self.nv)
            return cs.Function("mass_matrix", [self._q], [mass], ["q"], ["M"])

        return self._cached(("crba",), build)

    def nonlinear_effects(self) -> cs.Function:
        """Coriolis, centrifugal and gravity terms: ``q, v -> nle (nv)`` (RNEA with a = 0)."""

        def build() -> cs.Function:
            tau = self._id_expr((), cs.SX(0, 1), "sym", "zero")
            return cs.Function("nonlinear_effects", [self._q, self._v], [tau], ["q", "v"], ["nle"])

        return self._cached(("nle",), build)

    def gravity(self) -> cs.Function:
        """Generalised gravity: ``q -> g (nv)`` (RNEA with v = a = 0)."""

        def build() -> cs.Function:
            tau = self._id_expr((), cs.SX(0, 1), "zero", "zero")
            return cs.Function("gravity", [self._q], [tau], ["q"], ["g"])

        return self._cached(("gravity",), build)

    # ------------------------------------------------------------------ centroidal
    def com(self) -> cs.Function:
        """Centre of mass: ``q -> com (3)`` in world."""

        def build() -> cs.Function:
            pos, _ = dynamics.center_of_mass(
                self._specs, self._kinematics("none"), self.mass, False
            )
            return cs.Function("com", [self._q], [pos], ["q"], ["com"])

        return self._cached(("com",), build)

    def com_velocity(self) -> cs.Function:
        """Centre-of-mass velocity: ``q, v -> vcom (3)`` in world axes."""

        def build() -> cs.Function:
            _, vel = dynamics.center_of_mass(self._specs, self._kinematics("sym"), self.mass, True)
            return cs.Function("com_velocity", [self._q, self._v], [vel], ["q", "v"], ["vcom"])

        return self._cached(("vcom",), build)

    def centroidal_momentum(self) -> cs.Function:
        """Centroidal momentum: ``q, v -> h (6)``: linear, then angular about the CoM (world)."""

        def build() -> cs.Function:
            kin = self._kinematics("sym")
            pos, _ = dynamics.center_of_mass(self._specs, kin, self.mass, False)
            h = dynamics.centroidal_momentum(self._specs, kin, pos)
            return cs.Function("centroidal_momentum", [self._q, self._v], [h], ["q", "v"], ["h"])

        return self._cached(("centroidal",), build)

    # ------------------------------------------------------------------ Lie group
    def integrate(self) -> cs.Function:
        """``q (nq), dq (nv) -> q_next (nq)``: ``q (+) dq`` (free-flyer: ``q * exp6(dq)``)."""

        def build() -> cs.Function:
            dq = cs.SX.sym("dq", self.nv)
            out = liegroup.integrate(self._specs, self._q, dq, self.nq)
            return cs.Function("integrate", [self._q, dq], [out], ["q", "dq"], ["q_next"])

        return self._cached(("integrate",), build)

    def difference(self) -> cs.Function:
        """``q0 (nq), q1 (nq) -> dq (nv)`` with ``integrate(q0, dq) = q1``."""

        def build() -> cs.Function:
            q0, q1 = cs.SX.sym("q0", self.nq), cs.SX.sym("q1", self.nq)
            out = liegroup.difference(self._specs, q0, q1, self.nv)
            return cs.Function("difference", [q0, q1], [out], ["q0", "q1"], ["dq"])

        return self._cached(("difference",), build)

    def tangent_map(self) -> cs.Function:
        """``q -> T (nq x nv)``, the derivative of ``integrate(q, dq)`` w.r.t. dq at 0."""

        def build() -> cs.Function:
            t = liegroup.tangent_map(self._specs, self._q, self.nq, self.nv)
            return cs.Function("tangent_map", [self._q], [t], ["q"], ["T"])

        return self._cached(("tangent_map",), build)
