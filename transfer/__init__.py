"""varcouple.transfer: L2 and pseudo-L2 projection between non-matching meshes.

Paper section 2.1: for a source space V and a target space W on meshes that
need not match, ``T = D^{-1} B`` with ``B`` the coupling matrix (eq. 3,
integrated over exact element intersections) and ``D`` the target mass matrix
(diagonal with the dual basis of eq. 4).

>>> from transfer import Mesh, FunctionSpace, Transfer
>>> T = Transfer.assemble(FunctionSpace(src, "P1"), FunctionSpace(dst, "P1"), "l2")
>>> v = T(u)
"""

from .errors import (FieldError, MeshError, MeshFileError, NoOverlapError, OverlapWarning, QuadratureError,
                     SpaceError, TransferError)
from .grid import StructuredGrid
from .mesh import Mesh
from .operators import Coupling, Transfer, coupling_operator
from .spaces import FunctionSpace

__all__ = ["Coupling", "FieldError", "FunctionSpace", "Mesh", "MeshError", "MeshFileError", "NoOverlapError",
           "OverlapWarning", "QuadratureError", "SpaceError", "StructuredGrid", "Transfer", "TransferError", "coupling_operator"]
