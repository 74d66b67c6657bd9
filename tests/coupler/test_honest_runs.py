"""A run never claims more than it did: unconverged inner solves, signals, a second run in
the same output directory and unwritable outputs end with a status that says what
happened, a non-zero exit and one line naming the cause (stand-in participants: fast)."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from coupler.cli import main
from coupler.errors import EXIT_CODES
from coupler.protocol.wire import SolveReport
from coupler.run.outdir import LOCK, OutputBusy, OutputLock
from coupler.run.solves import StepSolves
from vc_helpers import CASES, copy_case, deliver_stopping_signals, stopping_signals_not_delivered

CASE = CASES / "standin_flow"


def summary(out):
    return json.loads((out / "summary.json").read_text())


def run(capsys, case, out):
    code = main(["run", str(case), "--output", str(out)])
    return code, capsys.readouterr().err


def test_an_unconverged_inner_solve_stops_the_run_as_not_converged(tmp_path, capsys):
    case = copy_case(CASE, tmp_path, {"feedback = 3.0e4": "feedback = 3.0e4\nunconverged = [1]"})
    out = tmp_path / "out"
    code, err = run(capsys, case, out)
    assert code == EXIT_CODES["not_converged"] == 3
    line = err.strip().splitlines()[-1]
    assert line.startswith("varcouple: error: not converged in time step 1, coupling iteration")
    assert "participant 'fluid': replay did not converge: residual 0.01 > 1e-06 after 10 iterations" in line
    s = summary(out)
    assert s["status"] == "not_converged" and "InnerSolveNotConverged" in s["error"]
    first, second = s["steps"]  # step 0 done and kept, step 1 recorded as not converged, nothing after
    assert first["converged"] and first["inner_converged"] and first["coupling_converged"]
    assert first["solves"]["fluid"][0]["converged"] and first["solves"]["solid"] == []
    assert second["coupling_converged"] and not second["inner_converged"] and not second["converged"]
    assert second["solves"]["fluid"][0] == {"solver": "replay", "converged": False, "iterations": 10,
                                            "residual": 0.01, "tolerance": 1e-6,
                                            "detail": "told to (config 'unconverged')", "accepted": False}
    assert (out / "solid_0001.vtu").is_file() and not (out / "solid_0002.vtu").exists()


@pytest.mark.parametrize("solver, table", [("platen", "the platen's [[loads]] entry"),
                                           ("contact active_set", "[contact]"),
                                           ("static CG+GAMG", "[solvers.solid]")])
def test_an_unconverged_solve_names_the_table_of_its_limits(solver, table):
    solves = StepSolves({})
    solves.add("solid", 0, [SolveReport(solver, False, 20, 3e-2, 1e-3)])
    message = str(solves.error(step=2))
    assert f"loosen its tolerance in {table}, or set [solvers.solid] allow_unconverged" in message
    assert "time step 2" in message and solver in message


def test_allow_unconverged_accepts_it_on_purpose_and_says_so(tmp_path, capsys):
    case = copy_case(CASE, tmp_path, {"feedback = 3.0e4": "feedback = 3.0e4\nunconverged = [1]\n"
                                                          "allow_unconverged = true"})
    out = tmp_path / "out"
    code = main(["run", str(case), "--output", str(out)])
    said, err = capsys.readouterr()
    assert code == 0, err
    assert [line for line in said.splitlines() if "accepted" in line] == [
        "warning: time step 1: participant 'fluid': replay did not converge: residual 0.01 > 1e-06 after 10 "
        "iterations (told to (config 'unconverged')); accepted (allow_unconverged)"]
    s = summary(out)
    assert s["status"] == "completed" and len(s["steps"]) == 4
    assert s["steps"][1]["converged"] and s["steps"][1]["accepted_unconverged"] == ["fluid: replay"]
    assert s["steps"][1]["solves"]["fluid"][0]["accepted"] and s["steps"][0]["accepted_unconverged"] == []


def _finish(proc, stderr: Path | None = None, timeout=60) -> str:
    """The stderr of `proc` (its pipe, or the file `stderr`) once it exits; if it does not within
    `timeout` s, the test fails with the stacks of its threads (the CLI dumps them on SIGUSR1)."""
    def read(timeout=None) -> str:
        if stderr is None:
            return proc.communicate(timeout=timeout)[1]
        proc.wait(timeout)
        return stderr.read_text()

    try:
        return read(timeout)
    except subprocess.TimeoutExpired:
        undelivered = stopping_signals_not_delivered(str(proc.pid))
        proc.send_signal(signal.SIGUSR1)
        time.sleep(2)
        proc.kill()
        signals = ", ".join(undelivered) or "SIGINT and SIGTERM neither ignored nor blocked"
        pytest.fail(f"the run did not stop within {timeout} s ({signals}); its threads:\n{read()[-6000:]}")


def _wait_for_steps(out, timeout=60):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            s = summary(out)
            if s.get("steps"):
                return s
        except (OSError, ValueError):
            pass
        time.sleep(0.05)
    raise AssertionError("the run wrote no step")


def _start_run(case, out, **popen):
    """`varcouple run` in a child process that receives SIGINT and SIGTERM whatever the test
    process inherited (a shell's background job ignores SIGINT)."""
    return subprocess.Popen([sys.executable, "-m", "coupler.cli", "run", str(case), "--output", str(out)],
                            preexec_fn=deliver_stopping_signals, **popen)


@pytest.mark.parametrize("sig, code, status, said", [(signal.SIGINT, 130, "interrupted", "interrupted"),
                                                     (signal.SIGTERM, 143, "terminated", "terminated by signal 15")],
                         ids=["ctrl_c", "sigterm"])
def test_a_signal_stops_the_participants_and_keeps_the_results(tmp_path, sig, code, status, said):
    case = copy_case(CASE, tmp_path, {"steps = 4": "steps = 100000"})
    out = tmp_path / "out"
    proc = _start_run(case, out, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for_steps(out)
    proc.send_signal(sig)
    err = _finish(proc)
    assert proc.returncode == code, err
    assert err.strip().splitlines()[-1].startswith(f"varcouple: error: {said}")
    s = summary(out)
    assert s["status"] == status and len(s["steps"]) >= 1
    time.sleep(0.5)
    for p in s["participants_announced"].values():
        with pytest.raises(ProcessLookupError):
            os.kill(p["pid"], 0)
    assert not (out / LOCK).exists()


def test_sigusr1_shows_where_a_run_is_and_the_run_goes_on(tmp_path):
    case = copy_case(CASE, tmp_path, {"steps = 4": "steps = 100000"})
    out = tmp_path / "out"
    proc = _start_run(case, out, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    steps = len(_wait_for_steps(out)["steps"])
    proc.send_signal(signal.SIGUSR1)
    time.sleep(1.0)
    assert len(summary(out)["steps"]) > steps  # still stepping
    proc.send_signal(signal.SIGINT)
    err = _finish(proc)
    assert proc.returncode == EXIT_CODES["interrupted"], err
    assert "most recent call first" in err and "coupler/cli.py" in err


def test_a_second_run_into_the_same_output_is_refused(tmp_path, capsys):
    case = copy_case(CASE, tmp_path, {"steps = 4": "steps = 100000"})
    out = tmp_path / "out"
    log = tmp_path / "first.err"
    first = _start_run(case, out, stdout=subprocess.DEVNULL, stderr=log.open("w"))
    try:
        s = _wait_for_steps(out)
        code, err = run(capsys, CASE, out)
        assert code == 2
        assert f"in use by run {s['run_id']} (pid {first.pid}" in err and "another --output" in err
        assert summary(out)["run_id"] == s["run_id"]  # the first run's files are untouched
    finally:
        first.send_signal(signal.SIGINT)
        _finish(first, log)


def test_a_stale_lock_is_taken_over(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / LOCK).write_text(json.dumps({"run_id": "old", "pid": dead.pid, "host": os.uname().nodename,
                                             "started": "yesterday"}))
    with OutputLock(tmp_path, "new") as lock:
        assert "stale lock of run old" in lock.note
        assert json.loads((tmp_path / LOCK).read_text())["run_id"] == "new"
        with pytest.raises(OutputBusy, match="in use by run new"):
            OutputLock(tmp_path, "third").acquire()
    assert not (tmp_path / LOCK).exists()


def test_an_unwritable_output_is_one_line_before_anything_runs(capsys):
    out = Path("/sys/varcouple-cannot-write-here")  # refused even to root
    code, err = run(capsys, CASE, out)
    assert code == 2 and "Traceback" not in err
    assert err.strip() == (f"varcouple: error: --output: cannot write to the output directory '{out}': "
                           f"Operation not permitted")


@pytest.mark.parametrize("replace, words", [
    ({"dt = 0.01": "dt = inf"}, ["[time] dt", "must be a finite number, got inf"]),
    ({"E = 1.0e9": "E = inf"}, ["[materials.solid] E", "finite"]),
    ({"nu = 0.25": "nu = nan"}, ["[materials.solid] nu", "finite"]),
    ({"upper = [1.0, 1.0, 1.0]": "upper = [1.0, inf, 1.0]"}, ["[geometry.fluid] upper", "finite numbers"]),
    ({"upper = [1.0, 1.0, 1.0]": "upper = [1e300, 1e300, 1e300]"},
     ["[geometry.fluid] upper", "coordinates up to 1e+300 in magnitude overflow double precision", "give the geometry in other units"]),
    ({"max_iterations = 30": "max_iterations = 30\n\n[messaging]\nmode = \"client\""},
     ["[messaging] connect", "client mode needs the zenoh router"]),
    ({"max_iterations = 30": "max_iterations = 30\n\n[messaging]\nconnect = [\"foo:bar\"]"},
     ["[messaging] connect", "'foo:bar' is not a zenoh endpoint"]),
    ({"max_iterations = 30": "max_iterations = 30\n\n[messaging]\nconnect = [\"tcp/127.0.0.1:99999\"]"},
     ["[messaging] connect", "port in 1..65535"]),
], ids=["dt_inf", "E_inf", "nu_nan", "grid_inf", "grid_1e300", "client_without_router", "malformed_endpoint", "bad_port"])
def test_scene_numbers_and_endpoints_are_checked_where_read(tmp_path, capsys, replace, words):
    case = copy_case(CASE, tmp_path, replace)
    code, err = run(capsys, case, tmp_path / "out")
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    for word in words:
        assert word in err, (word, err)
    assert not (tmp_path / "out").exists()  # nothing ran, nothing written


def test_an_unreachable_router_is_one_line_after_the_connect_timeout(tmp_path, capsys):
    case = copy_case(CASE, tmp_path, {"max_iterations = 30": "max_iterations = 30\n\n[messaging]\nmode = \"client\"\n"
                                                             "connect = [\"tcp/127.0.0.1:9\"]\ntimeout = 2"})
    start = time.monotonic()
    code, err = run(capsys, case, tmp_path / "out")
    assert code == 4 and time.monotonic() - start < 15 and "Traceback" not in err
    assert err.strip() == ("varcouple: error: cannot reach tcp/127.0.0.1:9 within 2 s: no zenoh router or peer "
                           "answers there (client mode)")
    assert summary(tmp_path / "out")["status"] == "failed"


SMALL = CASE.parent / "small_fracture"


@pytest.mark.parametrize("case, replace, key, cells", [
    (SMALL, {"shape = [21, 11, 11]": "shape = [1000, 1000, 1000]"}, "[geometry.fluid] shape", "1,000,000,000 fluid"),
    (CASE, {"shape = [4, 4, 3]": "shape = [2000, 2000, 2000]"}, "[geometry.solid] shape", "48,000,000,000 solid"),
    (CASE, {"max_iterations = 30": "max_iterations = 30\n[resources]\nmemory_limit = 1e8"},
     "[geometry.fluid] shape", "1,000 fluid"),
], ids=["grid_1000_cubed", "box_2000_cubed", "small_memory_limit"])
def test_a_scene_that_cannot_fit_in_memory_is_refused_before_anything_starts(tmp_path, capsys, case, replace, key,
                                                                             cells):
    case = copy_case(case, tmp_path, replace)
    for command in (["check", str(case)], ["run", str(case), "--output", str(tmp_path / "out")]):
        code = main(command)
        err = capsys.readouterr().err
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        assert key in err and cells in err and "available" in err and "check_memory = false" in err, err
    assert not (tmp_path / "out").exists()
    # the override: the estimate is still printed, nothing refused
    (case / "scene.toml").write_text((case / "scene.toml").read_text() + "\n[resources]\ncheck_memory = false\n"
                                     if "[resources]" not in (case / "scene.toml").read_text() else
                                     (case / "scene.toml").read_text() + "check_memory = false\n")
    assert main(["check", "--quick", str(case)]) == 0
    assert "available" in capsys.readouterr().out


@pytest.mark.skipif(not Path("/usr/bin/simpleFoam").exists(), reason="needs Debian's OpenFOAM")
def test_a_capped_simplefoam_is_not_reported_as_converged(tmp_path, capsys):
    """small_fracture with [solvers.fluid] max_iterations = 1 gave exit 0, 'completed' and a
    displacement 2.8x too small; now: exit 3, the solver, step, iteration and residual named."""
    case = copy_case(SMALL, tmp_path, {"max_iterations = 3000": "max_iterations = 1", "steps = 2": "steps = 1"})
    out = tmp_path / "out"
    code, err = run(capsys, case, out)
    assert code == 3, err
    line = err.strip().splitlines()[-1]
    assert "not converged in time step 0, coupling iteration" in line
    assert "participant 'fluid': simpleFoam did not converge: residual" in line and "after 1 iteration" in line
    assert "[solvers.fluid]" in line and "allow_unconverged" in line
    s = summary(out)
    assert s["status"] == "not_converged" and not s["steps"][0]["converged"]
    report = s["steps"][0]["solves"]["fluid"][0]
    assert report["solver"] == "simpleFoam" and not report["converged"] and report["residual"] > 1e-7
    assert s["steps"][0]["solves"]["solid"][0]["converged"]  # the solid's Krylov solve is reported too


def test_a_stopped_participant_is_named_as_stopped_in_one_line(tmp_path):
    """SIGSTOP of the solid: the run ends with exit 4 and one line saying the solid is stopped (it
    said 'died'); the coupler's own notes (liveliness tokens lost) go to logs/coupler.log, not
    after the error line."""
    case = copy_case(CASE, tmp_path, {"steps = 4": "steps = 100000"})
    out = tmp_path / "out"
    proc = _start_run(case, out, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    pid = _wait_for_steps(out)["participants_announced"]["solid"]["pid"]
    os.kill(pid, signal.SIGSTOP)
    err = _finish(proc, timeout=120)  # the run's end kills the stopped solid
    assert proc.returncode == EXIT_CODES["failed"], err
    lines = [line for line in err.splitlines() if not line.startswith("case [")]  # the progress bar
    assert len(lines) == 1 and lines[0].startswith("varcouple: error: "), err
    assert lines[0].endswith(f"participant 'solid' is stopped: process {pid} is stopped (state T: SIGSTOP or "
                             f"SIGTSTP); kill -CONT {pid} resumes it"), err
    assert summary(out)["status"] == "failed"
    assert "participant solid: liveliness token lost" in (out / "logs" / "coupler.log").read_text()
