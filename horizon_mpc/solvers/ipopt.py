"""IPOPT through CasADi ``nlpsol`` on the problem's transcription (built once).

Options (``make_solver('ipopt', prb, opts)``):

=================== ======== ==========================================================
``max_iter``        3000     IPOPT iteration limit
``tol``             1e-8     IPOPT convergence tolerance
``constr_viol_tol`` 1e-8     IPOPT constraint-violation tolerance
``print_level``     0        IPOPT verbosity (0..12)
``print_time``      False    CasADi's timing printout
``linear_solver``   'mumps'  IPOPT linear solver: 'mumps', 'spral', or HSL's 'ma27', 'ma57',
                             'ma77', 'ma86', 'ma97' where its library is installed
``sym``             'SX'     graph type of the transcription ('SX' or 'MX')
``constraint_rows`` 'valid'  'valid' (node sets change freely) or 'active' (smaller
                             NLP; see :class:`~horizon_mpc.problem.transcription.
                             Transcription`)
``warm_start_duals`` True    keep multipliers between solves and start IPOPT from them
``warm_mu_init``    1e-4     barrier parameter of a warm solve (cold solves: IPOPT's)
``warm_bound_push`` 1e-6     ``warm_start_bound_push``/``_mult_bound_push`` when warm
``ipopt.<name>``    -        any other IPOPT option, passed through unchecked
``nlpsol.<name>``   -        any CasADi nlpsol option (e.g. ``nlpsol.expand``)
=================== ======== ==========================================================

IPOPT options cannot change on an ``nlpsol`` instance, so a warm solve runs a second
instance (``warm_start_init_point yes``) built once, on first need, from the same NLP.
Changing an option with :meth:`set_option` rebuilds the instances, never the NLP.
"""

from __future__ import annotations

import ctypes.util
import logging
import math
import time
from typing import Any

import casadi as cs

from horizon_mpc.problem import Problem
from horizon_mpc.solvers.nlp_solver import NlpSolver

__all__ = ["IpoptSolver", "hsl_available"]

log = logging.getLogger(__name__)


class IpoptSolver(NlpSolver):
    """Interior-point solve of the full NLP (general costs allowed).

    Attributes:
        transcription: the :class:`Transcription` (``transcription.nlp`` is the NLP).
        lam_x, lam_g: multipliers of the last solve (None before), kept for warm starts.
    """

    name = "ipopt"
    DEFAULTS: dict[str, Any] = {
        "max_iter": 3000, "tol": 1e-8, "constr_viol_tol": 1e-8, "print_level": 0,
        "print_time": False, "linear_solver": "mumps", "sym": "SX", "constraint_rows": "valid",
        "warm_start_duals": True,
        "warm_mu_init": 1e-4, "warm_bound_push": 1e-6,
    }
    RANGES = {"max_iter": ">=0", "tol": ">0", "constr_viol_tol": ">0", "print_level": "[0,12]",
              "warm_mu_init": ">0", "warm_bound_push": ">0"}
    _IPOPT_ALIASES = ("max_iter", "tol", "constr_viol_tol", "print_level", "linear_solver")
    CHOICES = {**NlpSolver.CHOICES,
               "linear_solver": ("mumps", "spral", "ma27", "ma57", "ma77", "ma86", "ma97")}

    def _check_together(self, opts: dict[str, Any]) -> None:
        # IPOPT loads HSL at the solve and failed there ('Invalid_Option', cost 0)
        if opts["linear_solver"].startswith("ma") and not hsl_available():
            raise ValueError(f"option 'linear_solver' of solver 'ipopt': "
                             f"{opts['linear_solver']!r} needs the HSL library (libhsl or "
                             "libcoinhsl), which is not installed here; use 'mumps' or "
                             "'spral'")

    def __init__(self, prb: Problem, opts: dict[str, Any] | None = None):
        super().__init__(prb, opts)
        self._solvers: dict[bool, cs.Function] = {}
        nlp = self.transcription.nlp  # the returned point's f and g, whatever IPOPT filled
        self._fg = cs.Function("ipopt_fg", [nlp["x"], nlp["p"]], [nlp["f"], nlp["g"]])

    def _passthrough_keys(self, opts: dict[str, Any]) -> list[str]:
        return [k for k in opts if k.startswith(("ipopt.", "nlpsol."))]

    def set_option(self, key: str, value: Any) -> None:
        """Change one option; the IPOPT instances are rebuilt on the next solve."""
        super().set_option(key, value)
        self._solvers.clear()

    # ------------------------------------------------------------------ instances
    def _nlpsol(self, warm: bool) -> cs.Function:
        if warm not in self._solvers:
            o = self.opts
            ipopt = {k: o[k] for k in self._IPOPT_ALIASES}
            if o["verbose"]:  # IPOPT's own iteration table
                ipopt["print_level"] = max(o["print_level"], 5)
            ipopt["sb"] = "yes"
            if warm:
                ipopt.update({"warm_start_init_point": "yes", "mu_init": o["warm_mu_init"],
                              "warm_start_bound_push": o["warm_bound_push"],
                              "warm_start_mult_bound_push": o["warm_bound_push"],
                              "warm_start_slack_bound_push": o["warm_bound_push"]})
            ipopt.update({k[6:]: v for k, v in o.items() if k.startswith("ipopt.")})
            nlp_opts = {"ipopt": ipopt, "print_time": o["print_time"], "error_on_fail": False}
            nlp_opts.update({k[7:]: v for k, v in o.items() if k.startswith("nlpsol.")})
            t0 = time.perf_counter()
            self._solvers[warm] = cs.nlpsol(f"ipopt_{'warm' if warm else 'cold'}", "ipopt",
                                            self.transcription.nlp, nlp_opts)
            log.debug("built %s ipopt instance in %.3f s", "warm" if warm else "cold",
                      time.perf_counter() - t0)
        return self._solvers[warm]

    # ------------------------------------------------------------------ solve
    def _solve(self) -> bool:
        tr = self.transcription
        lbx, ubx = tr.bounds_w()
        lbg, ubg = tr.bounds_g()
        args = {"x0": self._initial_w(), "p": tr.parameters(), "lbx": lbx, "ubx": ubx,
                "lbg": lbg, "ubg": ubg}
        warm = bool(self.opts["warm_start_duals"] and self.lam_x is not None)
        if warm:
            args.update(lam_x0=self.lam_x, lam_g0=self.lam_g)
        solver = self._nlpsol(warm)
        t0 = time.perf_counter()
        res = solver(**args)
        elapsed = time.perf_counter() - t0
        st = solver.stats()
        w = res["x"].full().ravel()
        # f and g of the returned point evaluated here: IPOPT leaves them unset when it
        # stops before its first evaluation (e.g. Invalid_Option: violation 0 was reported
        # for a point violating by 3.9)
        f, g = self._fg(w, args["p"])
        g = g.full().ravel()
        self.w = w
        self.lam_x, self.lam_g = res["lam_x"].full().ravel(), res["lam_g"].full().ravel()
        self._split_solution(*tr.unpack(w))
        s = self.stats
        s.success = bool(st.get("success", False))
        s.status = str(st.get("return_status", "unknown"))
        # iter_count is garbage when IPOPT stopped before iterating (no iteration log then)
        s.iterations = int(st.get("iter_count", 0)) if "iterations" in st else 0
        s.time = elapsed
        s.cost = float(f)
        s.constraint_violation = tr.violation(w, g, lbx, ubx, lbg, ubg)
        if s.status == "Invalid_Number_Detected":
            # IPOPT stopped on a NaN/inf of the functions: its point says nothing
            s.cost = s.constraint_violation = math.nan
        s.history = []
        s.extra = {"warm": warm}
        log.debug("ipopt %s: %s in %d iterations, %.4f s, cost %.6g, violation %.2e",
                  "warm" if warm else "cold", s.status, s.iterations, s.time, s.cost,
                  s.constraint_violation)
        return s.success


def hsl_available() -> bool:
    """Whether IPOPT can load HSL's linear solvers (a libhsl or libcoinhsl on the library
    path)."""
    return any(ctypes.util.find_library(name) for name in ("hsl", "coinhsl"))
