"""An output that cannot be written during a run (a full disk, a directory made read-only)
fails the run with exit 4, status ``failed`` and one line naming the file, and leaves no
partial file: every file in the output directory is whole (stand-in participants: fast).

The faults are injected in this process: the files the coupler opens for writing under the
output directory go through :class:`Disk`, which fails the chosen write as the kernel does
(ENOSPC from ``write``, naming no file; EACCES from ``open``, ``rename`` and ``unlink``)."""

from __future__ import annotations

import builtins
import errno
import io
import json
import os
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import pytest

from coupler.cli import main
from coupler.errors import EXIT_CODES
from coupler.run.outdir import LOCK, OutputLock
from transfer.atomic import atomic_path, partial_name, write_text
from vc_helpers import CASES, copy_case

CASE = CASES / "standin_flow"
QUICK = {"steps = 4": "steps = 4\n\n[output]\npictures = false"}


class _Full:
    """A file being written on a disk that fills up: half of the first write lands, then ENOSPC."""

    def __init__(self, file):
        self._file, self._full = file, False

    def write(self, data):
        if not self._full:
            self._full = True
            self._file.write(data[:len(data) // 2])
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return self._file.write(data)

    def __getattr__(self, name):
        return getattr(self._file, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._file.close()


class Disk:
    """Writes under `directory`: the `nth` time a file whose name (without a leading dot) starts
    with `prefix` is opened for writing, the disk is full (mode ``"full"``: that one write fails,
    the space is back once the file is removed) or the directory becomes read-only (mode
    ``"read-only"``: that open and every later write, rename or removal there is refused)."""

    def __init__(self, monkeypatch, directory: Path, prefix: str, nth: int, mode: str):
        self.directory, self.prefix, self.nth, self.mode = Path(directory).resolve(), prefix, nth, mode
        self.seen, self.read_only = 0, False
        real_open, real_replace, real_unlink, real_os_open = builtins.open, os.replace, os.unlink, os.open

        def opened(file, mode="r", *args, **kwargs):
            if isinstance(file, (str, Path)) and any(c in mode for c in "wax+") and self._under(file):
                self._refuse_if_read_only(file)
                if Path(file).name.lstrip(".").startswith(self.prefix):
                    self.seen += 1
                    if self.seen == self.nth:
                        if self.mode == "full":
                            return _Full(real_open(file, mode, *args, **kwargs))
                        self.read_only = True
                        self._refuse_if_read_only(file)
            return real_open(file, mode, *args, **kwargs)

        def guarded(real):
            def call(path, *args, **kwargs):
                if self._under(path):
                    self._refuse_if_read_only(path)
                return real(path, *args, **kwargs)
            return call

        def replace(src, dst, *args, **kwargs):
            if self._under(dst):
                self._refuse_if_read_only(dst)
            return real_replace(src, dst, *args, **kwargs)

        monkeypatch.setattr(builtins, "open", opened)
        monkeypatch.setattr(io, "open", opened)
        monkeypatch.setattr(os, "replace", replace)
        monkeypatch.setattr(os, "rename", replace)
        monkeypatch.setattr(os, "unlink", guarded(real_unlink))
        monkeypatch.setattr(os, "remove", guarded(real_unlink))
        monkeypatch.setattr(os, "open", guarded(real_os_open))

    def _under(self, path) -> bool:
        try:
            return Path(os.fspath(path)).resolve().is_relative_to(self.directory)
        except TypeError:  # a file descriptor
            return False

    def _refuse_if_read_only(self, path) -> None:
        if self.read_only:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), os.fspath(path))


def _run(capsys, case, out):
    code = main(["run", str(case), "--output", str(out)])
    return code, capsys.readouterr().err


def _error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.startswith("varcouple: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _whole_files(out: Path) -> None:
    """Every file the run left is whole: no partial or temporary file, every VTU readable, every
    .pvd naming files that exist."""
    left = sorted(p.name for p in out.iterdir() if p.is_file())
    assert not [n for n in left if ".partial-" in n or n.endswith(".tmp")], left
    for vtu in out.glob("*.vtu"):
        meshio.read(vtu)
    for pvd in out.glob("*.pvd"):
        for data in ET.parse(pvd).getroot().iter("DataSet"):
            assert (out / data.get("file")).is_file(), (pvd.name, data.get("file"))


@pytest.mark.parametrize("prefix, nth, file", [("solid_0002", 1, "solid_0002.vtu"), ("solid.", 3, "solid.pvd"),
                                               ("summary", 3, "summary.json")],
                         ids=["vtu", "pvd", "summary"])
def test_a_full_disk_names_the_file_fails_the_run_and_leaves_whole_files(tmp_path, capsys, monkeypatch, prefix,
                                                                         nth, file):
    case = copy_case(CASE, tmp_path, QUICK)
    out = tmp_path / "out"
    Disk(monkeypatch, out, prefix, nth, "full")
    code, err = _run(capsys, case, out)
    monkeypatch.undo()
    assert code == EXIT_CODES["failed"] == 4, err
    line = _error_line(err)
    assert f"{out / file}: No space left on device" in line, line
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and file in summary["error"] and "No space left" in summary["error"]
    assert 1 <= len(summary["steps"]) <= 2
    _whole_files(out)
    assert not (out / LOCK).exists()


def test_a_directory_made_read_only_names_the_file_not_the_lock(tmp_path, capsys, monkeypatch):
    case = copy_case(CASE, tmp_path, QUICK)
    out = tmp_path / "out"
    Disk(monkeypatch, out, "solid_0002", 1, "read-only")
    code, err = _run(capsys, case, out)
    monkeypatch.undo()
    assert code == EXIT_CODES["failed"], err
    line = _error_line(err)
    assert f"{out / 'solid_0002.vtu'}: Permission denied" in line and LOCK not in line, line
    assert f"{out / 'summary.json'} not updated (Permission denied)" in line
    summary = json.loads((out / "summary.json").read_text())  # whole: the last step's
    assert summary["status"] == "running" and len(summary["steps"]) == 2
    _whole_files(out)


def test_an_atomic_write_that_fails_leaves_the_previous_file(tmp_path):
    path = tmp_path / "a.json"
    write_text(path, "old")
    with pytest.raises(OSError) as raised, atomic_path(path) as tmp:
        tmp.write_text("new, half written")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert raised.value.filename == str(path) and raised.value.errno == errno.ENOSPC
    assert path.read_text() == "old" and os.listdir(tmp_path) == ["a.json"]


def test_the_next_run_removes_the_partial_files_of_a_killed_one(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    killed = partial_name(tmp_path / "solid_0002.vtu", dead.pid)
    killed.write_text("<VTKFile")
    alive = partial_name(tmp_path / "fluid_0002.vtu", os.getpid())
    alive.write_text("<VTKFile")
    with OutputLock(tmp_path, "next"):
        assert not killed.exists() and alive.exists()


@pytest.mark.skipif(os.geteuid() != 0, reason="chattr +i needs root")
def test_a_directory_made_immutable_during_a_run(tmp_path):
    """The real thing (root ignores permissions, not the immutable flag): the run ends with exit 4
    naming the file it could not write, not the lock."""
    case = copy_case(CASE, tmp_path, {"steps = 4": "steps = 100000\n\n[output]\npictures = false"})
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "coupler.cli", "run", str(case), "--output", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (out / "solid_0001.vtu").exists():
            time.sleep(0.05)
        if subprocess.run(["chattr", "+i", str(out)], capture_output=True).returncode:
            proc.kill()
            pytest.skip("this file system has no immutable flag")
        err = proc.communicate(timeout=60)[1]
    finally:
        subprocess.run(["chattr", "-i", str(out)], capture_output=True)
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == EXIT_CODES["failed"], err
    line = _error_line(err)
    assert f"{out}/" in line and "Operation not permitted" in line and LOCK not in line, line
    assert "summary.json not updated" in line
    assert json.loads((out / "summary.json").read_text())["status"] == "running"  # whole, the last step's
