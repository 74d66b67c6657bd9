"""Field file I/O of fluid_openfoam.fields: round trips in ASCII and binary, and a
cross-check against OpenFOAM itself (foamFormatConvert rewrites our binary file as ASCII)."""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest

from fluid_openfoam import case as fcase
from fluid_openfoam.fields import FieldFormatError, read_internal_field, replace_internal_field, write_field
from fluid_openfoam.solver import openfoam_env

BND = "    walls { type zeroGradient; }"


@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("n", [1, 7, 1000])
@pytest.mark.parametrize("vector", [False, True])
def test_round_trip(tmp_path, binary, n, vector):
    rng = np.random.default_rng(n)
    values = rng.standard_normal((n, 3) if vector else n) * 10.0 ** rng.integers(-300, 300, (n, 3) if vector else n)
    path = tmp_path / "f"
    write_field(path, values, BND, binary=binary)
    back = read_internal_field(path, n)
    assert back.shape == values.shape
    np.testing.assert_array_equal(back, values)  # repr / raw bytes: exact
    head = path.read_bytes()[:300]
    assert (b"format      binary" in head) == binary
    assert (b"volVectorField" in head) == vector


@pytest.mark.parametrize("binary", [True, False])
def test_replace_keeps_boundary(tmp_path, binary):
    path = tmp_path / "U"
    write_field(path, np.zeros((5, 3)), "    inlet { type fixedValue; value uniform (1 0 0); }", binary=binary)
    new = np.arange(15.0).reshape(5, 3)
    replace_internal_field(path, new)
    np.testing.assert_array_equal(read_internal_field(path, 5), new)
    assert b"value uniform (1 0 0);" in path.read_bytes()


def test_uniform_and_inline(tmp_path):
    hdr = "FoamFile { version 2.0; format ascii; class volVectorField; object U; }\n"
    (tmp_path / "U").write_text(hdr + "dimensions [0 1 -1 0 0 0 0];\ninternalField   uniform (1 2 3);\n"
                                "boundaryField { }\n")
    np.testing.assert_array_equal(read_internal_field(tmp_path / "U", 4), np.tile([1.0, 2, 3], (4, 1)))
    (tmp_path / "p").write_text(hdr.replace("volVectorField", "volScalarField")
                                + "internalField nonuniform List<scalar> 3(1 2.5 -3e-7);\nboundaryField { }\n")
    np.testing.assert_array_equal(read_internal_field(tmp_path / "p"), [1, 2.5, -3e-7])
    with pytest.raises(FieldFormatError, match="expected 4"):
        read_internal_field(tmp_path / "p", 4)
    with pytest.raises(ValueError, match="NaN"):
        write_field(tmp_path / "bad", np.array([1.0, np.nan]), BND)


@pytest.mark.skipif(shutil.which("foamFormatConvert") is None, reason="OpenFOAM not installed")
def test_openfoam_reads_our_binary(tmp_path):
    """Our binary file, converted to ASCII by OpenFOAM's foamFormatConvert, reads back equal."""
    spec = fcase.CaseSpec.from_config({"grid": {"origin": [0, 0, 0], "spacing": [1, 1, 1], "shape": [3, 2, 2]}})
    fcase.write_case(tmp_path, spec)
    env = openfoam_env()
    subprocess.run(["blockMesh", "-case", str(tmp_path)], check=True, capture_output=True, env=env)
    rng = np.random.default_rng(0)
    u, s = rng.standard_normal((12, 3)), rng.random(12)
    replace_internal_field(tmp_path / "0" / "U", u)  # 0/U is ascii+uniform: becomes nonuniform ascii
    write_field(tmp_path / "0" / "solid", s, fcase.boundary_scalar_passive(spec.faces), obj="solid", binary=True)
    write_field(tmp_path / "0" / "U", u, fcase.boundary_u(spec.faces), obj="U", binary=True,
                dimensions="[0 1 -1 0 0 0 0]")
    cd = tmp_path / "system" / "controlDict"
    cd.write_text(cd.read_text().replace("writeFormat     binary", "writeFormat     ascii"))
    subprocess.run(["foamFormatConvert", "-case", str(tmp_path)], check=True, capture_output=True, env=env)
    head = (tmp_path / "0" / "U").read_bytes()[:1000]
    assert re.search(rb"format\s+ascii;", head), head
    np.testing.assert_allclose(read_internal_field(tmp_path / "0" / "U", 12), u, rtol=1e-15)
    np.testing.assert_allclose(read_internal_field(tmp_path / "0" / "solid", 12), s, rtol=1e-15)
