"""The one ParaView collection writer (transfer.meshfile.write_pvd), used by the coupler's
series and the solid participant's VTU series."""

import xml.etree.ElementTree as ET

from transfer.meshfile import write_pvd


def test_a_collection_lists_each_file_with_its_time(tmp_path):
    write_pvd(tmp_path / "solid.pvd", [(0.0, "solid_0000.vtu"), (0.1 + 0.2, "solid_0001.vtu"), (1e-5, "s_2.vtu")])
    root = ET.parse(tmp_path / "solid.pvd").getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    sets = [(d.get("timestep"), d.get("file")) for d in root.find("Collection")]
    assert sets == [("0", "solid_0000.vtu"), ("0.3", "solid_0001.vtu"), ("1e-05", "s_2.vtu")]
