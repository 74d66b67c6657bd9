"""The ``varcouple`` command line.

    varcouple transfer SRC DST --field NAME -o OUT [--method l2|pseudo_l2]
    varcouple check CASE
    varcouple run CASE [--output DIR]
    varcouple study CASE --vary KEY=VALUES [--vary ...] [--output DIR] [--figure PATH | --field P.F] [--max-runs N]

``main(argv)`` returns the exit code: 0 on success, 2 on a usage or input error
(bad option, missing file or field, invalid scene, meshes that do not overlap),
which is printed as one line ``varcouple: error: <message>`` on stderr, without
a traceback. Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import sys
import time

PROG = "varcouple"


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        ours = version("varcouple")
    except PackageNotFoundError:
        ours = "unknown"
    py = ".".join(map(str, sys.version_info[:3]))
    return f"{PROG} {ours} [Python {py}]"


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


# -- varcouple transfer ----------------------------------------------------------
def _transfer_args(parser: argparse.ArgumentParser) -> None:
    from transfer.operators import METHODS
    from transfer.quadrature import MAX_DEGREE

    parser.add_argument("source", metavar="SRC", help="source mesh file carrying the field (any format meshio reads)")
    parser.add_argument("target", metavar="DST", help="target mesh file (any format meshio reads)")
    parser.add_argument("--field", "-f", required=True, metavar="NAME",
                        help="field of SRC to transfer: point data (-> P1/Q1) or cell data (-> P0/Q0)")
    parser.add_argument("--output", "-o", required=True, metavar="OUT",
                        help="output mesh file (DST's mesh with the field and 'covered'; format by extension)")
    parser.add_argument("--method", "-m", choices=METHODS, default="l2",
                        help="l2: full target mass matrix; pseudo_l2: dual basis, diagonal mass (default: l2)")
    parser.add_argument("--quadrature-degree", "-q", type=_positive_int, default=None, metavar="N",
                        help=f"quadrature degree on the intersections, 1 to {MAX_DEGREE} "
                             f"(default: exact for the bases)")
    parser.add_argument("--threads", "-t", type=_positive_int, default=1, metavar="N",
                        help="threads of the assembly kernel (default: 1)")


def _mpi_job() -> tuple[int, int]:
    """(rank, ranks) of the MPI job mpirun started this process in; (0, 1) outside one."""
    import os

    for rank, size in (("OMPI_COMM_WORLD_RANK", "OMPI_COMM_WORLD_SIZE"), ("PMI_RANK", "PMI_SIZE")):
        if size in os.environ:
            return int(os.environ.get(rank, 0)), int(os.environ[size])
    return 0, 1


def transfer(args: argparse.Namespace) -> int:
    """Transfer one field from SRC to DST and write DST with it to OUT. Under
    ``mpirun -n N`` rank 0 reads both files, once, and sends every rank its part of each mesh
    (coordinate bisection, the two meshes cut independently), while a ``.pvtu`` is read in
    parts, each rank its own pieces; the operator is assembled and applied on the N ranks and
    rank 0 writes the same file as a serial run."""
    from transfer import TransferError

    from coupler.errors import CouplerError

    rank, ranks = _mpi_job()
    try:
        return _transfer(args, rank, ranks)
    except (CouplerError, TransferError, OSError):
        if rank == 0:
            raise
        raise SystemExit(2) from None  # rank 0 found the error and says it


def _checked(args, source, target, field, say) -> None:
    """The field `field` of `source` may go to OUT with DST's cells (`target`, a MeshFile of them)."""
    import numpy as np

    from coupler.errors import CouplerError

    target.check_keeps(args.output, {field.name: (field.kind, field.values),
                                     "covered": (field.kind, np.zeros(0, np.uint8))})
    if field.kind == "point" and source is not None and args.field in source.raw.cell_data:
        say(f"note: {args.field!r} is both point and cell data in {source.path}; using the point data")
    if args.field == "covered":
        raise CouplerError(f"{args.source}: field name 'covered' is reserved for the coverage mask of the "
                           f"output; rename the field")


def _read(args, say):
    """SRC and DST read, the field found and checked against OUT's format, what they hold
    said: (source, target, field)."""
    from transfer.meshfile import MeshFile

    source = MeshFile.read(args.source)
    target = MeshFile.read(args.target)
    field = source.field(args.field)
    _checked(args, source, target, field, say)
    say(f"source  {source.path}: {source.describe()}; {field.describe()} -> {source.space(field.kind).family}")
    say(f"target  {target.path}: {target.describe()} -> {target.space(field.kind).family}")
    return source, target, field


def _transfer(args: argparse.Namespace, rank: int, ranks: int) -> int:
    import numpy as np

    from transfer import QuadratureError
    from transfer.pieces import read_in_parts
    from transfer.quadrature import check_degree

    from coupler.errors import CouplerError
    from transfer.meshfile import MeshFile, check_writable

    say = print if rank == 0 else (lambda *a, **k: None)
    if args.quadrature_degree is not None:
        try:
            check_degree(args.quadrature_degree)
        except QuadratureError as exc:
            raise CouplerError(f"--quadrature-degree: {exc}") from None
    check_writable(args.output, inputs=(args.source, args.target))
    if ranks > 1 or read_in_parts(args.source) or read_in_parts(args.target):  # .pvtu, .xdmf: read in parts, on any ranks
        p, target, field = _project_distributed(args, say)
        if p is None:
            return 0
    else:
        from coupler.run.projection import project

        source, target, field = _read(args, say)
        _say_reads([(MeshFile.reads, MeshFile.cells_read, MeshFile.points_read)], say)
        p = project(field, source.space(field.kind), target.space(field.kind), args.method,
                    quadrature_degree=args.quadrature_degree, threads=args.threads)
    stats = p.operator.stats
    quadrature = stats.get("quadrature_degree")
    quadrature = "exact moments" if quadrature == "exact" else f"degree {quadrature}"
    where = f" x {ranks} MPI ranks" if ranks > 1 else ""
    print(f"method  {args.method} (quadrature: {quadrature}; {args.threads} thread{'s' * (args.threads > 1)}{where})")
    print(f"assembly {p.assembly_seconds:.3f} s (intersection kernel {p.kernel_seconds:.3f} s; "
          f"{stats.get('pairs_intersected', '?')} of {stats.get('pairs_tested', '?')} cell pairs intersect); "
          f"apply {1e3 * p.apply_seconds:.1f} ms")
    print(f"covered {100 * p.covered_fraction:.2f}% of {len(p.covered)} target dofs "
          f"({p.uncovered} uncovered, NaN in the output)")
    for text in p.operator.warnings:
        print(f"warning: {text}")
    print(f"conservation error {p.conservation_error:.2e} (relative difference of the integrals over the overlap)")
    target.write(args.output, {field.name: (field.kind, p.values),
                               "covered": (field.kind, p.covered.astype(np.uint8))})
    print(f"wrote   {args.output}: {field.kind} data {field.name!r}, 'covered'")
    return 0


def _say_reads(reads, say) -> None:
    """What each rank read: `reads` holds (files, cells, points) per rank (None off rank 0)."""
    if reads is not None:
        files, cells, points = (list(r) for r in zip(*reads))
        say(f"read    files opened per rank {files}; cells read per rank {cells}, points {points}")


def _on_root(comm, work):
    """`work()` on rank 0, its result there (None elsewhere); when it fails, rank 0 raises its
    error and the other ranks a CouplerError (unsaid: rank 0 says it)."""
    from coupler.errors import CouplerError

    result, failure = None, None
    if comm.rank == 0:
        try:
            result = work()
        except Exception as exc:  # noqa: BLE001 - the other ranks wait to hear it
            failure = exc
    if comm.bcast(failure is not None):
        if failure is not None:
            raise failure
        raise CouplerError("rank 0 could not read the files")
    return result


def _project_distributed(args, say):
    """The field carried on all ranks of MPI.COMM_WORLD, each holding its part of both meshes:
    the pieces of a ``.pvtu`` it reads itself (:class:`transfer.pieces.Pieces`); another file
    rank 0 reads, once, and sends each rank its part (:func:`transfer.distributed.scatter`).
    Then (projection, target file, field) on rank 0, the projection as
    :func:`coupler.run.projection.project` gives it, (None, None, None) on the others."""
    import warnings

    from mpi4py import MPI

    import transfer.petsc  # noqa: F401 - PETSc starts before the clock: its initialisation is not assembly
    from transfer import OverlapWarning, Transfer
    from transfer.distributed import gather, scatter
    from transfer.mesh import Mesh
    from transfer.meshfile import MeshFile, MeshFileField, family
    from transfer.pieces import Pieces, read_in_parts

    from coupler.run.projection import Projection

    comm = MPI.COMM_WORLD
    pieces = {key: Pieces.open(getattr(args, key), comm) for key in ("source", "target")
              if read_in_parts(getattr(args, key))}
    if not pieces:
        source, target, field = _on_root(comm, lambda: _read(args, say)) or (None, None, None)
    else:
        files = _on_root(comm, lambda: {key: MeshFile.read(getattr(args, key)) for key in ("source", "target")
                                        if key not in pieces}) or {}
        field = pieces["source"].field(args.field) if "source" in pieces else _on_root(
            comm, lambda: files["source"].field(args.field))
        source, target = files.get("source"), files.get("target")
        _on_root(comm, lambda: _checked(args, source, target or pieces["target"].held[0], field, say))
        for key, what in (("source", source), ("target", target)):
            if key in pieces:
                p = pieces[key]
                say(f"{key:7} {p.path}: {p.num_cells} {p.cell_type} cells, {p.num_points} points, in pieces")
            elif what is not None:
                say(f"{key:7} {what.path}: {what.describe()}")
    kind, shape = comm.bcast((field.kind, field.values.shape[1:]) if comm.rank == 0 else None)
    files = {"source": source, "target": target}
    parts, u = {}, None
    for key in ("source", "target"):
        if key in pieces:
            parts[key], first = pieces[key].part(family(Mesh.empty(pieces[key].cell_type), kind))
            if key == "source":
                u = field.flat[first] if kind == "point" else field.flat
        else:
            mesh = files[key] and files[key].mesh
            parts[key], values = scatter(mesh, comm.bcast(mesh and family(mesh, kind)),
                                         field and field.flat if key == "source" else None, comm)
            u = values if key == "source" else u
    source = files["source"] = None  # rank 0 keeps a target file alone: the output is that mesh with the field
    field = field and MeshFileField(field.name, kind, field.values[:0])
    _say_reads(comm.gather((MeshFile.reads, MeshFile.cells_read, MeshFile.points_read)), say)
    start = time.perf_counter()
    with warnings.catch_warnings(action="ignore", category=OverlapWarning):
        operator = Transfer.assemble(parts["source"], parts["target"], args.method, comm=comm,
                                     quadrature_degree=args.quadrature_degree, nthreads=args.threads)
    assembly = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    start = time.perf_counter()
    v = operator(u)
    apply = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    conservation = operator.conservation_error(u, v)
    values, covered = gather(parts["target"], v, comm), gather(parts["target"], operator.covered, comm)
    operator_stats, operator_warnings = operator.stats, operator.warnings
    del operator, parts
    if "target" in pieces:
        files["target"] = pieces["target"].whole()
    if comm.rank:
        return None, None, None
    whole = _Gathered(operator_stats, operator_warnings, covered)
    return (Projection(args.method, whole, values.reshape((len(values),) + shape), assembly, apply, conservation),
            files["target"], field)


class _Gathered:
    """What a :class:`coupler.run.projection.Projection` reads of its operator, for the
    distributed operator gathered on rank 0."""

    def __init__(self, stats: dict, warnings: list, covered):
        self.stats, self.warnings, self.covered = stats, warnings, covered

    @property
    def covered_fraction(self) -> float:
        return float(self.covered.mean())


# -- varcouple check -------------------------------------------------------------
def check(args: argparse.Namespace) -> int:
    """Validate the scene of CASE and print its plan: effects, participants to start,
    fields that cross, transfer operators to build; estimate its size and memory, and
    have each participant read its part (meshes, boundaries) without solving anything
    (``--quick``: the scene alone)."""
    from coupler import scene as scenes
    from coupler.plan.plan import make_plan
    from coupler.run.preflight import check_cores, check_memory, estimate, first_step

    scene = scenes.load(args.case)
    print(f"scene         {scene.path}: valid")
    plan = make_plan(scene)
    for line in plan.lines():
        print(line)
    if scene.check:
        from coupler.checks import KINDS

        print(f"check         {scene.check['kind']}: {KINDS[scene.check['kind']].DESCRIPTION} "
              f"(tolerance {scene.check['tolerance']:g})")
    check_cores(scene, scene.coupling["ranks"])
    estimates = estimate(scene)
    print("size          " + "; ".join(f"{e.name} {e.cells:,} cells" for e in estimates if e.cells))
    print(f"memory        {check_memory(scene, estimates)}")
    step, warning = first_step(scene, estimates)
    if step:
        print(f"time          {step}")
    if warning:
        print(f"warning       {warning}")
    if not args.quick:
        from coupler.run.runner import rehearse

        for name, mesh in rehearse(scene, plan).items():
            print(f"configured    {name}: {plan.participant(name).kind} accepts its part "
                  f"({mesh.num_cells:,} cells, {mesh.num_points:,} points); operators built")
    print(f"output        {scene.output_dir}")
    return 0


# -- varcouple run ---------------------------------------------------------------
def _run_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("case", metavar="CASE", help="case directory holding scene.toml (or the scene file)")
    parser.add_argument("--output", "--out", "-o", metavar="DIR", default=None,
                        help="output directory (default: [output] directory of the scene, in the case)")


def run(args: argparse.Namespace) -> int:
    """Validate the scene of CASE, run it and write its outputs. Exit code by the final
    status (README, "When a run fails"): 0 completed, 1 the [check] failed, 2 invalid input,
    3 not converged, 4 failed, 130 interrupted (Ctrl-C), 143 terminated (SIGTERM)."""
    from coupler import scene as scenes
    from coupler.errors import EXIT_CODES
    from coupler.run.execute import execute

    from coupler.run.execute import coupler_ranks, job_size
    from coupler.run.job import relaunch

    start = time.perf_counter()
    scene = scenes.load(args.case, output=args.output)
    ranks = coupler_ranks(scene)
    if ranks > 1 and job_size() == 1:  # [coupling] ranks = P: this command again on P ranks
        return relaunch(["run", args.case] + (["--output", args.output] if args.output is not None else []), scene,
                        ranks)
    origin = "--output" if args.output is not None else f"{scene.path}: [output] directory"
    summary = execute(scene, origin, log=_log)
    if not summary.get("check", {}).get("passed", True):
        _log(f"done in {time.perf_counter() - start:.1f} s; results in {scene.output_dir}; the [check] FAILED")
        return EXIT_CODES["check_failed"]
    _log(f"done in {time.perf_counter() - start:.1f} s; results in {scene.output_dir}")
    return EXIT_CODES["completed"]


def _log(line: str) -> None:
    if not _mpi_job()[0]:  # rank 0 of a coupler on several ranks speaks for all
        print(line, flush=True)


# -- varcouple study -------------------------------------------------------------
def study(args: argparse.Namespace) -> int:
    """Run the scene of CASE over the product of the --vary values, each run in its own
    directory under the study's (default: <[output] directory>/study), through the same path as
    `varcouple run`; write study.json (the study's status and planned runs; per run: values,
    status, seconds per phase and total, cost in cells, error), study.png (error against wall
    time and cost) and index.html. The error is a per-step figure's (--figure), a field's
    (--field) or the scene's [check]'s, against the most accurate run. Before any run: the runs
    are counted (more than --max-runs are refused), every one validated, what is compared
    checked against the plan, and the count and an estimate of the time printed. Exit code 0
    when every run completed (and passed its [check]), 1 when some did not (study.json says
    which), 2 for a bad scene, key, value or option (nothing runs), 130/143 on Ctrl-C/SIGTERM
    (study.json records every run started, the one stopped with its status)."""
    from coupler.errors import EXIT_CODES
    from coupler.run.study import run_study

    result = run_study(args.case, args.vary, args.output, args.field, args.figure, args.max_runs, log=_log)
    return EXIT_CODES["completed"] if result["status"] == "completed" else EXIT_CODES["check_failed"]


# -- main ----------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Partitioned multiphysics coupling through L2 / pseudo-L2 projections "
                    "between non-matching meshes.",
        formatter_class=argparse.RawTextHelpFormatter,
    )
    parser.add_argument("--version", "-v", action="version", version=_version(),
                        help="display version information")
    sub = parser.add_subparsers(title="subcommands", dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("transfer", help="transfer a field between two mesh files",
                       description=transfer.__doc__)
    _transfer_args(p)
    p.set_defaults(func=transfer)

    p = sub.add_parser("check", help="validate a case's scene and print its plan", description=check.__doc__)
    p.add_argument("case", metavar="CASE", help="case directory holding scene.toml (or the scene file)")
    p.add_argument("--quick", action="store_true",
                   help="validate the scene and estimate its size only; start no participant")
    p.set_defaults(func=check)

    p = sub.add_parser("run", help="run a case (cases/NAME with its scene.toml)", description=run.__doc__)
    _run_args(p)
    p.set_defaults(func=run)

    p = sub.add_parser("study", help="run a case over the product of scene values; error against time and cost",
                       description=study.__doc__)
    p.add_argument("case", metavar="CASE", help="case directory holding scene.toml (or the scene file)")
    p.add_argument("--vary", action="append", required=True, metavar="KEY=VALUES",
                   help="a dotted scene key and a TOML array of its values, e.g. "
                        "'coupling.acceleration=[\"aitken\", \"iqn-ils\"]' (repeatable: the product is run)")
    p.add_argument("--output", "--out", "-o", metavar="DIR", default=None,
                   help="the study's directory (default: the scene's [output] directory/study)")
    p.add_argument("--field", default=None, metavar="PARTICIPANT.FIELD",
                   help="the field compared with the reference run (relative L2 difference; default: the scene's "
                        "[check] if it has one, else solid.displacement)")
    p.add_argument("--figure", default=None, metavar="PATH",
                   help="a per-step number of summary.json as a dotted path (e.g. fracture.hydraulic_aperture): "
                        "each run's error is its relative error against the reference run, per step")
    p.add_argument("--max-runs", type=_positive_int, default=None, metavar="N",
                   help="refuse a study of more than N runs before anything runs (default 100)")
    p.set_defaults(func=study)
    return parser


def error(message: str) -> None:
    if _mpi_job()[0]:  # every rank of an MPI job finds the same error: rank 0 says it
        return
    print(f"{PROG}: error: {' '.join(str(message).split())}", file=sys.stderr, flush=True)


def _terminate(signum, frame):
    from coupler.errors import Terminated

    raise Terminated(signum)


def main(argv: list[str] | None = None) -> int:
    from coupler.protocol.mpi import confine
    from coupler.protocol.mpi_session import mpi_session

    with mpi_session():  # the run's own Open MPI files, removed at its end
        confine()  # before MPI starts in this process: it listens on loopback only (coupler/protocol/mpi.py)
        return _main(argv)


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a usage error argparse has printed
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)

    import faulthandler
    import signal

    from transfer import TransferError

    from coupler.errors import EXIT_CODES, CouplerError, NotConverged, RunFailed, Terminated, one_line

    try:  # kill -USR1 PID: every thread's stack to stderr (a run that hangs says where)
        faulthandler.register(signal.SIGUSR1, all_threads=True)
    except (AttributeError, OSError, ValueError):  # no SIGUSR1, or stderr is not a file (captured)
        pass
    try:  # SIGTERM (timeout, batch schedulers) ends a run like Ctrl-C: participants stopped, results kept
        previous = signal.signal(signal.SIGTERM, _terminate)
    except ValueError:  # not the main thread
        previous = None
    try:
        return args.func(args)
    except Terminated as exc:
        error(one_line(exc, f"{exc}: participants stopped, the results written so far are kept"))
        return EXIT_CODES["terminated"]
    except KeyboardInterrupt as exc:
        error(one_line(exc, "interrupted: participants stopped, the results written so far are kept"))
        return EXIT_CODES["interrupted"]
    except NotConverged as exc:
        error(one_line(exc))
        return EXIT_CODES["not_converged"]
    except RunFailed as exc:
        error(one_line(exc))
        return EXIT_CODES["failed"]
    except (CouplerError, TransferError, OSError) as exc:
        sys.stdout.flush()
        error(one_line(exc))
        return EXIT_CODES["invalid"]
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
