"""nonsmooth: solvers for bound-constrained quadratic programs (paper 2.2 and 2.4).

Contact in the transformed system of paper eq. 10 and the obstacle problem both
reduce to one algebraic problem (:class:`BoundConstrainedQP`)::

    minimise  1/2 x^T A x - b^T x   subject to   lower <= x <= upper

with ``A`` symmetric positive definite and bounds nodewise (``-inf``/``+inf``
where a component is free). This package knows matrices and vectors only: no
meshes and no dolfinx. The solvers share one result type (:class:`Solution`).
"""

from .problem import BoundConstrainedQP, Control, NonsmoothSolveError, Solution

__all__ = ["BoundConstrainedQP", "Control", "NonsmoothSolveError", "Solution"]
