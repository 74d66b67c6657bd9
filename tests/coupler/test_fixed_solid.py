"""A fixed immersed solid (effects ["flow"] without "elasticity"): a stand-in served in the
coupler's process (rigid_solid: its mesh, zero displacement), a one-way plan (the solid
fraction only, one fluid solve per step), generated geometry and its grid
(transfer/generators/plates.py), the fraction sampled exactly or at the cell centres, and the
errors of scenes that ask a fixed solid for what only an elastic one has."""

from __future__ import annotations

import numpy as np
import pytest

from coupler.errors import SceneError
from coupler.fsi.centres import centres_inside
from coupler.fsi.interface import SolidOnGrid
from coupler.plan.plan import make_plan
from coupler.protocol.errors import ParticipantError
from coupler.run.local import LocalClient
from coupler.run.runner import processes
from coupler.scene import load
from coupler.standins import RigidSolid
from transfer import StructuredGrid
from transfer.generate import box_tetrahedra
from transfer.generators import GENERATORS, parameters
from vc_helpers import CASES, copy_case

CASE = CASES / "parallel_plates"


def plates(n: int, offset: float):
    """The plates generator's solid and grid for n cells across, the lower face at offset."""
    p = parameters("plates", {"aperture": 1e-3, "length": 2e-3, "cells_across": n, "offset": offset})
    g = GENERATORS["plates"].grid(p)
    return GENERATORS["plates"].mesh(p).mesh, StructuredGrid(g["origin"], g["spacing"], g["shape"])


def test_the_plan_is_one_way_around_a_solid_served_in_process():
    scene = load(CASE)
    plan = make_plan(scene)
    solid, fluid = plan.participants
    assert (solid.name, solid.kind, solid.in_process) == ("solid", "rigid_solid", True)
    assert solid.config == {"generator": scene.solid.generator}
    assert (fluid.name, fluid.kind, fluid.in_process) == ("fluid", "openfoam", False)
    (exchange,) = plan.exchanges
    assert (exchange.sources, exchange.target, exchange.operator, exchange.options) == (
        ["solid.displacement"], "fluid.solid_fraction", "solid_fraction", {"fraction": "exact"})
    assert not plan.implicit and "one-way (a fixed solid): one fluid solve per step" in plan.iteration
    assert "served in the coupler's process" in plan.lines()[1]
    assert scene.solvers.keys() == {"fluid"} and scene.material == {} and scene.loads == []
    grid = scene.fluid
    assert (grid.origin, grid.spacing, grid.shape) == ([0.0, 0.0, 0.0], [5e-4, 1.25e-4, 1.25e-4], [4, 13, 1])


@pytest.mark.parametrize("old, new, message", [
    ("[check]", '[coupling]\ninterface = "ymax"\n[check]',
     "[coupling] interface: a fixed solid (no 'elasticity') is not loaded by the fluid"),
    ("[check]", "[materials.solid]\nE = 1e9\nnu = 0.3\n[check]",
     "[materials] solid: the material of a deforming solid, but no effect of ['flow'] deforms one"),
    ("[check]", '[[loads]]\ntype = "dirichlet"\nboundary = "xmin"\n[check]',
     "[[loads]]: loads act on a deforming solid, but no effect of ['flow'] deforms one"),
    ("[solvers.fluid]", '[solvers.solid]\nparticipant = "spring_solid"\n[solvers.fluid]',
     "[solvers] solid: no effect of ['flow'] needs a solid participant"),
    ('generator = "plates"            # 4', 'generator = "box"  # 4', "[geometry.fluid] generator: 'box': the grid comes from the solid's generator, and "
                                                 "[geometry.solid] generator is 'plates'"),
    ('generator = "plates"            # 4', 'generator = "plates"\nshape = [4, 13, 1]  # 4',
     "[geometry.fluid] shape: the grid comes from generator 'plates'; give no other key"),
    ("cells_across = 8 ", "cells_across = 0 ", "[geometry.solid.parameters] cells_across: must lie in [1, inf)"),
    ("offset = 0.25 ", "offset = 1.0 ", "[geometry.solid.parameters] offset: must lie in [0.0, 1.0)"),
    ("aperture = 1.0e-3 ", "apperture = 1.0e-3 ", "[geometry.solid.parameters] apperture: unknown parameter of "
                                                   "generator 'plates'"),
    ('generator = "plates"            # transfer', 'generator = "spheres"  # transfer',
     "[geometry.solid] generator: unknown value 'spheres'; use one of 'fracture_specimen', 'hertz', 'measured_fracture', "
     "'penny_crack', 'plates'"),
    ('solid_fraction = "exact"', 'solid_fraction = "mask"', "[flow] solid_fraction: unknown value 'mask'"),
])
def test_what_a_fixed_solid_has_not_is_named(tmp_path, old, new, message):
    with pytest.raises(SceneError) as info:
        load(copy_case(CASE, tmp_path, {old: new}))
    assert "scene.toml: " + message in str(info.value)


def test_a_rigid_solid_serves_its_mesh_and_stays_put():
    client = LocalClient("solid", RigidSolid())
    client.configure({"box": {"lower": [0, 0, 0], "upper": [1, 2, 3], "shape": [1, 2, 1]}})
    header, fields = client.geometry()
    assert header["cell_type"] == "tetra" and fields["cells"].data.shape == (12, 4)
    out = client.advance(0, 0, 0.0, 1.0, {})
    assert set(out) == {"displacement", "velocity"} and not np.any(out["displacement"].data)
    assert client.last_solves == [] and client.stats["calls"] == 3
    assert client.announce()["kind"] == "rigid_solid"
    with pytest.raises(ParticipantError,  # bad input: a ParticipantInputError
                       match=r"participant 'solid' refused its input: InputError: rigid_solid: needs config"):
        client.configure({})


class RankOfTwo:
    """Rank `rank` of two coupler ranks whose other rank made the mesh of digest `other` (None: the same)."""

    def __init__(self, rank: int, other=None):
        self.rank, self.other = rank, other

    def Get_rank(self):
        return self.rank

    def Get_size(self):
        return 2

    def allgather(self, value):
        mine = [value, value]
        mine[1 - self.rank] = self.other or value
        return mine


BOX = {"box": {"lower": [0, 0, 0], "upper": [1, 2, 3], "shape": [2, 2, 1], "jitter": 0.2, "seed": 1}}


def test_a_rigid_solid_on_two_ranks_serves_its_part():
    """Bound to rank r of 2 (a coupler on 2 ranks serves it on each), it serves part r of its mesh
    (transfer.partition.part_rows): the cells of both parts are the mesh's once, each point owned
    once, and its outputs are the zero rows of the points it owns."""
    whole = LocalClient("solid", RigidSolid())
    whole.configure(BOX)
    mesh = whole.handler.mesh
    seen_cells, seen_points = [], []
    for rank in (0, 1):
        solid = RigidSolid()
        solid.bind("r1", "solid", RankOfTwo(rank))
        client = LocalClient("solid", solid)
        client.configure(BOX)
        (part,) = client.exchange("geometry", None, [None, None])
        f = {k: np.asarray(getattr(v, "data", v)) for k, v in part.fields.items()}
        np.testing.assert_array_equal(f["cells"], mesh.cells[f["cell_ids"]])
        np.testing.assert_array_equal(f["points"], mesh.points[f["point_ids"]])
        (out,) = client.exchange("advance", {"window": 0, "iteration": 0, "t": 0.0, "dt": 1.0}, [None, None])
        assert out.fields["displacement"].data.shape == (len(f["point_ids"]), 3)
        assert not np.any(out.fields["velocity"].data)
        seen_cells.append(f["cell_ids"])
        seen_points.append(f["point_ids"])
    assert all(len(c) for c in seen_cells)
    np.testing.assert_array_equal(np.sort(np.concatenate(seen_cells)), np.arange(mesh.num_cells))
    np.testing.assert_array_equal(np.sort(np.concatenate(seen_points)), np.arange(mesh.num_points))


def test_a_rigid_solid_made_otherwise_on_another_rank_is_an_error():
    """Each rank makes the whole mesh: one that made another (a generator that depended on the rank)
    fails the configure, naming how it was made and the rank."""
    solid = RigidSolid()
    solid.bind("r1", "solid", RankOfTwo(1, other="another digest"))
    with pytest.raises(ParticipantError, match=r"rigid_solid \(its box\): rank 0 made another mesh than rank 1 "
                                               r"\(each rank makes it whole"):
        LocalClient("solid", solid).configure(BOX)


def test_a_plan_served_in_process_opens_no_session():
    plan = make_plan(load(CASE))
    with processes(load(CASE), plan, "r1", "logs") as (session, launcher):
        assert session is not None and launcher is not None  # the fluid is a process
    plan.participants = plan.participants[:1]
    with processes(load(CASE), plan, "r1", "logs") as (session, launcher):
        assert (session, launcher) == (None, None)


def test_exact_fractions_are_the_intersection_volumes():
    """n = 4, offset 0.3: the lower face cuts the third row of cells at 0.3, the upper one the
    seventh at 0.3 of the way up (fractions 0.3 and 0.7); every column alike."""
    mesh, G = plates(4, 0.3)
    f = SolidOnGrid(mesh, G, None, "test", wetted=False).fraction.reshape(9, 4)
    np.testing.assert_allclose(f[:, 0], [1, 1, 0.3, 0, 0, 0, 0.7, 1, 1], atol=1e-12)
    np.testing.assert_allclose(f, f[:, :1] * np.ones((1, 4)), atol=1e-12)


def test_cell_centres_on_the_solid_s_faces_are_inside():
    """Offset 0.5 puts cell centres exactly on both faces: both count as solid (the old mask's
    closed boxes); offset 0.25 leaves the gap n cells wide."""
    for offset, row in ((0.5, [1, 1, 1, 0, 0, 0, 1, 1, 1]), (0.25, [1, 1, 0, 0, 0, 0, 1, 1, 1])):
        mesh, G = plates(4, offset)
        inside = centres_inside(mesh, G).reshape(9, 4)
        assert inside[:, 0].tolist() == [bool(v) for v in row] and (inside == inside[:, :1]).all()


def test_cell_centres_inside_a_jittered_mesh_agree_with_a_brute_force_test():
    S = box_tetrahedra((3, 4, 2), lower=(0.1, 0.2, 0.05), upper=(0.77, 0.9, 0.6), jitter=0.2, seed=2)
    G = StructuredGrid([0, 0, 0], [0.05, 0.07, 0.03], [20, 15, 25])
    x = G.cell_centers()
    brute = np.zeros(len(x), bool)
    for tet in S.points[S.cells]:
        lam = np.linalg.solve((tet[1:] - tet[0]).T, (x - tet[0]).T).T
        brute |= (lam.min(axis=1) >= -1e-9) & (lam.sum(axis=1) <= 1 + 1e-9)
    inside = centres_inside(S, G)
    assert np.array_equal(inside, brute) and 0 < inside.sum() < len(x)
    # a box of cells [0.2, 0.6] x [0.28, 0.77] x [0.09, 0.54] whose centres are surely inside
    assert inside.sum() == pytest.approx(S.cell_measures().sum() / np.prod(G.spacing), rel=0.1)


def test_a_solid_the_fluid_does_not_load_may_leave_the_grid():
    """The volume fallback of a loaded solid needs the grid to cover it; a fixed solid does not."""
    S = box_tetrahedra((2, 2, 2), lower=(-0.5, 0, 0), upper=(0.5, 1, 1))
    G = StructuredGrid([0, 0, 0], [0.25, 0.25, 0.25], [4, 4, 4])
    on_grid = SolidOnGrid(S, G, None, "[geometry.fluid]", wetted=False)
    assert on_grid.interface is None and on_grid.outside == pytest.approx(0.5)
    assert on_grid.fraction.reshape(4, 4, 4)[:, :, :2].min() == pytest.approx(1.0)
    with pytest.raises(Exception, match=r"\[geometry.fluid\]: the fluid grid does not cover the solid"):
        SolidOnGrid(S, G, None, "[geometry.fluid]")
