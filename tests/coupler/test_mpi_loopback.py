"""Open MPI in a single-host run listens on no network interface (coupler/protocol/mpi.py): not the
ranks of a participant under mpirun, not a single process that initialises MPI (the solid with
one rank), not the OpenFOAM solver's ranks; mpirun's wire-up goes over loopback.
Sockets are read from /proc (/proc/<pid>/fd and /proc/net/tcp, tcp6)."""

from __future__ import annotations

import ipaddress
import json
import os
import shutil
import socket
import struct
import subprocess
import sys
import textwrap
import time
import uuid
from pathlib import Path

import pytest

from coupler.run.launch import Launcher, descendants
from coupler.run.client import CouplerSession
from coupler.protocol.mpi import INTERFACES_VAR, confine, loopback_library, mpi_environment
from fluid_openfoam.case import CaseSpec
from fluid_openfoam.parallel import Decomposition
from fluid_openfoam.solver import OpenFOAMSolver
from vc_helpers import ROOT

TESTS = Path(__file__).resolve().parent
needs_mpirun = pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")


def _address(hex_addr: str) -> str:
    raw = bytes.fromhex(hex_addr)
    words = b"".join(struct.pack("<I", int.from_bytes(raw[i:i + 4], "big")) for i in range(0, len(raw), 4))
    return socket.inet_ntop(socket.AF_INET if len(raw) == 4 else socket.AF_INET6, words)


def listeners(pids) -> dict[int, list[tuple[str, int]]]:
    """{pid: [(address, port)]} of the TCP sockets each process listens on."""
    listening = {}
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            f = line.split()
            if f[3] == "0A":  # TCP_LISTEN
                addr, port = f[1].split(":")
                listening[f[9]] = (_address(addr), int(port, 16))
    out = {}
    for pid in pids:
        inodes = set()
        try:
            for fd in os.listdir(f"/proc/{pid}/fd"):
                try:
                    target = os.readlink(f"/proc/{pid}/fd/{fd}")
                except OSError:
                    continue
                if target.startswith("socket:["):
                    inodes.add(target[8:-1])
        except OSError:
            continue
        out[pid] = sorted(listening[i] for i in inodes if i in listening)
    return out


def exposed(found: dict[int, list[tuple[str, int]]]) -> dict[int, list[tuple[str, int]]]:
    """The listeners not on a loopback address (0.0.0.0, :: or an interface's address)."""
    bad = {pid: [s for s in socks if not ipaddress.ip_address(s[0]).is_loopback] for pid, socks in found.items()}
    return {pid: socks for pid, socks in bad.items() if socks}


def comm(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return "?"


def wait_for(path: Path, proc, seconds: float = 60) -> None:
    t0 = time.monotonic()
    while not path.exists() or "ready" not in path.read_text():
        assert proc.returncode is None, path.read_text() if path.exists() else "exited"
        assert time.monotonic() - t0 < seconds, f"not ready after {seconds} s"
        time.sleep(0.05)


@needs_mpirun
def test_participant_ranks_listen_on_no_network(tmp_path):
    """A 2-rank participant started by the Launcher: mpirun, its ranks (and any orted) listen
    nowhere but on loopback (Open MPI's TCP BTL used to listen on 0.0.0.0:1024 and [::]:1024)."""
    coupler = CouplerSession(f"test-{uuid.uuid4().hex[:12]}")
    with coupler, Launcher(coupler.run_id, tmp_path, coupler.endpoints) as launcher:
        proc = launcher.start("solid", "coupler.standins", ranks=2, extra_args=["--kind", "echo"])
        client = coupler.client("solid", timeout=60)
        client.wait_alive(60)
        assert client.announce()["ranks"] == 2
        below = descendants(proc.pid)
        assert len([p for p in below if comm(p).startswith("python")]) == 2
        found = listeners([proc.pid, *below])
        assert not exposed(found), {f"{comm(p)}[{p}]": s for p, s in exposed(found).items()}


def test_a_single_process_that_initialises_mpi_listens_nowhere(tmp_path):
    """A participant on one rank that imports mpi4py (as the dolfinx solid does): Open MPI's
    singleton start used to fork an orted and listen on all interfaces, both."""
    (tmp_path / "vc_mpi_single.py").write_text(textwrap.dedent("""\
        import time
        from mpi4py import MPI
        MPI.COMM_WORLD.Barrier()
        print("ready", flush=True)
        time.sleep(60)
        """))
    env = dict(os.environ, PYTHONPATH=f"{tmp_path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    with Launcher(f"t-{uuid.uuid4().hex[:8]}", tmp_path, env=env) as launcher:
        proc = launcher.start("solid", "vc_mpi_single")
        wait_for(proc.log_path, proc)
        tree = [proc.pid] + descendants(proc.pid)
        assert [comm(p) for p in tree if comm(p) == "orted"] == []
        assert listeners(tree) == {proc.pid: []}


@needs_mpirun
@pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="OpenFOAM not installed")
def test_openfoam_ranks_listen_on_no_network(tmp_path, monkeypatch):
    """OpenFOAMSolver.run of the application on 2 ranks (mpi_command), with a stand-in
    'simpleFoam' that initialises MPI and records what each rank listens on."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "simpleFoam"
    fake.write_text(f"#!{sys.executable}\n" + textwrap.dedent(f"""\
        import json, os, sys
        sys.path[:0] = [{str(TESTS)!r}, {str(ROOT / "tests")!r}]
        from mpi4py import MPI
        from test_mpi_loopback import listeners
        MPI.COMM_WORLD.Barrier()
        found = listeners([os.getpid()])[os.getpid()]
        MPI.COMM_WORLD.Barrier()
        with open(os.path.join({str(tmp_path)!r}, f"rank{{MPI.COMM_WORLD.rank}}.json"), "w") as f:
            json.dump(found, f)
        """))
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    spec = CaseSpec.from_config({"grid": {"origin": [0, 0, 0], "spacing": [1, 1, 1], "shape": [2, 2, 2]}}, ranks=2)
    (tmp_path / "case").mkdir()
    solver = OpenFOAMSolver(tmp_path / "case", spec)
    solver.parallel = Decomposition(solver.case, spec)  # mpi_command only: nothing to decompose
    solver.run("simpleFoam")
    for rank in range(2):
        found = [tuple(s) for s in json.loads((tmp_path / f"rank{rank}.json").read_text())]
        assert not exposed({rank: found}), found


@needs_mpirun
def test_mpirun_wires_up_over_loopback(tmp_path):
    """mpirun's contact address (what its daemons and ranks connect to) is 127.0.0.1 only."""
    out = subprocess.run(["mpirun", "-n", "1", "--report-uri", "-", "true"], capture_output=True, text=True,
                         env=mpi_environment(env=os.environ), timeout=60, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    uri = out.stdout.strip().splitlines()[0]
    addresses = [part.split("//", 1)[1].rsplit(":", 1)[0].strip("[]") for part in uri.split(";")[1:]]
    assert addresses and all(ipaddress.ip_address(a).is_loopback for a in addresses), uri


@needs_mpirun
def test_mpirun_itself_listens_on_loopback_only(tmp_path):
    """Open MPI 4.1's mpirun binds its out-of-band listener to the wildcard address whatever
    oob_tcp_if_include says: the preloaded library binds it to loopback (without it this fails)."""
    proc = subprocess.Popen(["mpirun", "-n", "1", sys.executable, "-c",
                             "import time; print('ready', flush=True); time.sleep(30)"],
                            stdout=subprocess.PIPE, text=True, env=mpi_environment(env=os.environ), cwd=tmp_path)
    try:
        assert proc.stdout.readline().strip() == "ready"
        found = listeners([proc.pid])
    finally:
        proc.kill()
        proc.wait()
    assert not exposed(found), found


def test_named_interfaces_for_several_hosts():
    """Several hosts: the interfaces named (argument, else VARCOUPLE_MPI_INTERFACES) carry MPI's
    TCP traffic and wire-up, replacing inherited one-host settings; on one host the settings the
    environment already has win."""
    env = mpi_environment(["eth0", "10.1.0.0/16"], env={})
    assert env["OMPI_MCA_btl"] == "self,vader,tcp"
    assert env["OMPI_MCA_btl_tcp_if_include"] == env["OMPI_MCA_oob_tcp_if_include"] == "eth0,10.1.0.0/16"
    assert mpi_environment(env={INTERFACES_VAR: "ib0, eth1"})["OMPI_MCA_oob_tcp_if_include"] == "ib0,eth1"
    single = mpi_environment(env={})
    assert single["OMPI_MCA_btl"] == "self,vader" and single["OMPI_MCA_oob_tcp_if_include"] == "lo"
    assert "OMPI_MCA_btl_tcp_if_include" not in single
    assert single["LD_PRELOAD"].split()[0] == loopback_library()  # mpirun's listener on loopback
    assert "LD_PRELOAD" not in env  # several hosts: mpirun must listen on the named interfaces
    assert mpi_environment(env={"LD_PRELOAD": "other.so"})["LD_PRELOAD"].split() == [loopback_library(), "other.so"]
    assert mpi_environment(env={"OMPI_MCA_btl": "self,tcp"})["OMPI_MCA_btl"] == "self,tcp"
    assert mpi_environment(["eth0"], env=single)["OMPI_MCA_oob_tcp_if_include"] == "eth0"
    with pytest.raises(ValueError):
        mpi_environment(["eth0 eth1"], env={})


def sample_listeners(argv, cwd, seconds: float = 120):
    """Run ``varcouple ARGV`` to its end, reading the listening sockets of its process and all
    its descendants every 50 ms; (the non-loopback listeners seen, how many readings found
    Open MPI loaded in the varcouple process). It must exit 0."""
    proc = subprocess.Popen([sys.executable, "-m", "coupler.cli", *map(str, argv)], cwd=cwd,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    seen, with_mpi, t0 = {}, 0, time.monotonic()
    try:
        while proc.poll() is None and time.monotonic() - t0 < seconds:
            tree = [proc.pid, *descendants(proc.pid)]
            try:
                with_mpi += "libmpi" in Path(f"/proc/{proc.pid}/maps").read_text()
            except OSError:
                pass
            for pid, socks in exposed(listeners(tree)).items():
                seen[f"{comm(pid)}[{pid}]"] = socks
            time.sleep(0.05)
    finally:
        proc.kill()
        err = proc.communicate()[1]
    assert proc.returncode == 0, err[-2000:]
    return seen, with_mpi


def test_a_default_run_listens_on_loopback_only(tmp_path):
    """``varcouple run`` on one rank: the coupler initialises MPI itself (petsc4py), as Open MPI's
    singleton, which listened on 0.0.0.0:1024 and [::]:1024 and forked an orted listening on all
    interfaces; no process of the run listens beyond loopback now."""
    case = tmp_path / "case"
    shutil.copytree(ROOT / "cases" / "standin_flow", case)
    scene = case / "scene.toml"
    scene.write_text(scene.read_text().replace("steps = 4", "steps = 30"))
    seen, with_mpi = sample_listeners(["run", case, "--output", tmp_path / "out"], tmp_path)
    assert with_mpi > 3, "MPI never seen loaded in the coupler: the test saw nothing"
    assert not seen, seen


def test_check_listens_on_loopback_only(tmp_path):
    """``varcouple check`` builds the operators in its own process (MPI, singleton) and starts
    the participants: all on loopback only."""
    seen, with_mpi = sample_listeners(["check", ROOT / "cases" / "standin_flow"], tmp_path)
    assert with_mpi > 3, "MPI never seen loaded in the coupler: the test saw nothing"
    assert not seen, seen


def test_the_test_process_itself_listens_on_loopback_only():
    """The tests initialise MPI in pytest's own process (tests/conftest.py confines it first)."""
    from mpi4py import MPI

    MPI.COMM_WORLD.Barrier()
    tree = [os.getpid(), *descendants(os.getpid())]
    assert [comm(p) for p in tree if comm(p) == "orted"] == []
    assert not exposed(listeners(tree))


def test_confine_sets_this_process_and_keeps_a_jobs_settings():
    """:func:`confine` writes the one-host settings into the environment given; in a process
    mpirun started, the settings of its job stay and only the missing ones are added."""
    alone = {"PATH": "/bin"}
    confine(alone)
    assert alone["OMPI_MCA_btl"] == "self,vader" and alone["OMPI_MCA_ess_singleton_isolated"] == "1"
    assert alone["PATH"] == "/bin"
    job = {"OMPI_COMM_WORLD_SIZE": "2", "OMPI_MCA_btl": "self,tcp", "OMPI_MCA_orte_ess_num_procs": "2"}
    confine(job)
    assert job["OMPI_MCA_btl"] == "self,tcp" and job["OMPI_MCA_orte_ess_num_procs"] == "2"
    assert job["OMPI_MCA_oob_tcp_if_include"] == "lo" and job["OMPI_COMM_WORLD_SIZE"] == "2"
    named = {INTERFACES_VAR: "eth0", "OMPI_MCA_btl": "self,vader"}
    confine(named)
    assert named["OMPI_MCA_btl_tcp_if_include"] == "eth0" and named["OMPI_MCA_btl"] == "self,vader,tcp"


def test_a_parents_singleton_leftovers_are_not_inherited():
    """A process that initialised MPI as an isolated singleton (pytest's, a script's) writes
    OMPI_MCA_ess=singleton and its like into its C environment; a varcouple run it starts inherited
    them and the participants' mpirun exited 1 without a word (a solid on 2 ranks 'died'). confine()
    drops them from this process, mpi_environment() from what it starts; a job's own settings stay."""
    from coupler.protocol.mpi import SINGLETON_VARIABLES, confine, mpi_environment

    leftovers = {"OMPI_MCA_ess": "singleton", "OMPI_MCA_pmix": "isolated", "OMPI_MCA_orte_ess_num_procs": "1",
                 "OMPI_APP_CTX_NUM_PROCS": "1", "OMPI_MCA_orte_precondition_transports": "84b7-e112"}
    assert set(leftovers) == set(SINGLETON_VARIABLES)
    env = {"PATH": "/usr/bin", **leftovers}
    assert not set(leftovers) & set(mpi_environment(env=env))
    confine(env)
    assert not set(leftovers) & set(env) and env["OMPI_MCA_btl"] == "self,vader"
    job = {"OMPI_COMM_WORLD_SIZE": "2", "OMPI_MCA_ess": "pmi"}  # inside mpirun's job: its settings stay
    confine(job)
    assert job["OMPI_MCA_ess"] == "pmi"
