"""The actuator interface: what the model, the NLP library and the methods need to know of an actuator.

An actuator is a self-contained component (like a SOFA constraint): it names the material points it acts
on, by their rest positions, and gives one scalar *quantity* Q of their current positions as a CasADi SX
expression (a cable: its length; a cavity: its volume). Everything else is derived from Q by CasADi:

    force on the nodes   u * sign * dQ/dx      (the row of H is sign * dQ/dx)
    tangent stiffness    -u * sign * d2Q/dx2   with the true sparsity of the SX Hessian
    NLP Hessian terms    third derivatives of Q, again by CasADi

``sign`` is the sign of the virtual work u * sign * dQ: a cable's tension does work by shortening it
(sign -1), a cavity's pressure by growing it (sign +1). The model embeds the points in the mesh (a gather
map W with positions = W x) and iterates over actuators; it knows no actuator kind.

Adding an actuator kind is one module with a class implementing this interface, plus its problem-file
reader.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["Actuator", "quantity_functions", "third_function"]


class Actuator:
    """Base class of actuators; subclasses set the attributes and implement :meth:`rest_points` and
    :meth:`quantity`."""

    kind: str = "actuator"
    """The actuator kind, as result files name it (``cable``)."""
    input_unit: str = ""
    """Unit of the input u (``N`` for a cable tension, ``Pa`` for a pressure)."""
    quantity_name: str = ""
    """Name of Q (``length``, ``volume``)."""
    quantity_unit: str = ""
    """Unit of Q (``m``, ``m^3``)."""
    sign: float = 1.0
    """Sign of the virtual work u * sign * dQ (see the module's docstring)."""
    name: str
    u_min: float
    u_max: float
    control: str = "force"
    """What the input u is: the actuator's intensity (``force`` for a cable's tension, ``pressure`` for a
    cavity) or its quantity, prescribed (``displacement``: a cable's shortening L0 - L in m, like SOFA's
    default valueType; ``volume``: a cavity's volume growth V - V0 in m^3, SOFA's volumeGrowth). With a
    prescribed quantity the intensity is an unknown of the equilibrium (see :mod:`casadi_ws.fem.model`)."""
    unilateral: bool = False
    """The intensity cannot change sign when the quantity is prescribed (a cable pulls, never pushes: it
    goes slack instead)."""
    intensity_unit: str = ""
    """Unit of the intensity (``N``, ``Pa``) whatever the control."""

    @property
    def prescribed(self) -> bool:
        """True when the input prescribes the quantity (displacement or volume control)."""
        return self.control in ("displacement", "volume")

    def rest_points(self) -> np.ndarray:
        """Rest positions (k, 3) of the material points Q depends on, in metres."""
        raise NotImplementedError

    def quantity(self, P: ca.SX) -> ca.SX:
        """Q as a scalar SX expression of the stacked current positions P (3k, point-major) of
        :meth:`rest_points`."""
        raise NotImplementedError

    def quantity_terms(self) -> tuple[ca.Function, np.ndarray] | None:
        """Q as a sum of small terms, or None (the default: Q taken whole): (f, idx) with Q(P) =
        sum_t f(P[idx[t]]), f a Function of a few coordinates, idx (n_terms, n_in) indices into P. Its
        derivatives are then those of f, summed (:func:`quantity_functions`), which costs far less than
        differentiating a whole surface's volume."""
        return None

    def quantity_limits(self, rest: float) -> tuple[float, float, str]:
        """Bounds on Q that a state must keep (a cable's stroke, a chamber's volume), given Q at rest, and
        the name of the violation (:mod:`casadi_ws.solvers.admissible`); none by default."""
        return -np.inf, np.inf, ""

    def describe(self) -> dict:
        """Plain data that determines the actuator (for result files and checkpoint fingerprints)."""
        return {"kind": self.kind, "name": self.name, "u_min": float(self.u_min), "u_max": float(self.u_max),
                "control": self.control, "points": np.asarray(self.rest_points(), dtype=float).tolist()}


def quantity_functions(actuator: Actuator) -> dict:
    """CasADi pieces of one actuator, derived from its quantity Q(P), P (3k) the stacked point positions:

    ``P``, ``Q``, ``dQ``, ``d2Q``   the SX symbol, Q, dQ/dP and the nonzeros of d2Q/dP2 (column-major in
                                  ``hessian_sparsity``); the model stacks these of all actuators into one
                                  function, as one CasADi call costs more than the arithmetic
    ``hessian_sparsity``          the structural pattern of d2Q/dP2 that CasADi derives from Q

    The third derivatives are :func:`third_function`'s, built only where they are used.
    """
    k = np.asarray(actuator.rest_points()).shape[0]
    P = ca.SX.sym("P", 3 * k)
    terms = actuator.quantity_terms()
    if terms is None:
        Q = actuator.quantity(P)
        g = ca.gradient(Q, P)
        H = ca.hessian(Q, P)[0]
    else:
        Q, g, H = _summed_derivatives(P, *terms)
    return {
        "P": P, "Q": Q, "dQ": g,
        "d2Q": ca.vertcat(*H.nonzeros()) if H.nnz() else ca.SX.zeros(0, 1),
        "hessian_sparsity": H.sparsity(),
    }


def _summed_derivatives(P, f: ca.Function, idx: np.ndarray):
    """(Q, dQ/dP, d2Q/dP2) of Q = sum_t f(P[idx[t]]): every term's derivatives by one mapped call, summed
    into P's by sparse 0/1 matrices (one product each, not one per term)."""
    import scipy.sparse as sps

    idx = np.asarray(idx, dtype=np.int64)
    m, n_in = idx.shape
    n = P.numel()
    x = ca.SX.sym("x", n_in)
    v = f(x)
    h, gx = ca.hessian(v, x)
    hr, hc = (np.asarray(a, dtype=np.int64) for a in h.sparsity().get_triplet())
    out = ca.Function("terms", [x], [v, gx, ca.vertcat(*h.nonzeros()) if h.nnz() else ca.SX(0, 1)]).map(m)
    X = ca.reshape(P[idx.ravel().tolist()], n_in, m)  # column t: the coordinates of term t
    vt, gt, ht = out(X)  # (1, m), (n_in, m), (nnz_h, m)

    def summed(rows, cols, values, shape):
        """The 0/1 matrix that adds values[j] into entry j's (rows[j], cols[j]) of the flat target."""
        S = sps.csc_matrix((np.ones(rows.size), (rows, cols)), shape=shape)
        return ca.mtimes(ca.DM(S), values)

    g = summed(idx.ravel(), np.arange(m * n_in).reshape(m, n_in).ravel(), ca.vec(gt), (n, m * n_in))
    R, C = idx[:, hr].ravel(), idx[:, hc].ravel()  # term-major, as vec(ht) runs
    pattern = sps.csc_matrix((np.ones(R.size), (R, C)), shape=(n, n))
    pattern.sum_duplicates()
    sp = ca.Sparsity(n, n, pattern.indptr.tolist(), pattern.indices.tolist())
    # position of each (R, C) among the pattern's nonzeros, which run column-major as CasADi stores them
    cols = np.repeat(np.arange(n), np.diff(pattern.indptr))
    key = np.searchsorted(cols * n + pattern.indices, C * n + R)
    nz = summed(key, np.arange(R.size), ca.vec(ht), (sp.nnz(), R.size))
    return ca.sum2(vt), g, ca.SX(sp, nz)


def third_function(actuator: Actuator) -> ca.Function:
    """Function (P, mu) -> d2(mu . dQ/dP)/dP2 (3k x 3k, CasADi's sparsity): the actuator's share of a
    Lagrangian Hessian, which only the full-space NLP needs. Apart from :func:`quantity_functions` because
    a cavity's took ~60 % of building a model (the third derivative of its whole surface's volume; 3 s of
    ~9 s for a 10-node hollow sphere), paid by every model that never uses it."""
    k = np.asarray(actuator.rest_points()).shape[0]
    P = ca.SX.sym("P", 3 * k)
    mu = ca.SX.sym("mu", 3 * k)
    T = ca.hessian(ca.dot(mu, ca.gradient(actuator.quantity(P), P)), P)[0]
    return ca.Function(f"{actuator.kind}_third", [P, mu], [T], ["P", "mu"], ["T"])
