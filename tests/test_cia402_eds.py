"""The shipped EDS files describe exactly the drive's object dictionary: they are what `protocol.cia402_eds` writes
from the default configuration, and python canopen's `import_od` of each reads back every object and sub-index of
`object_dictionary()` with its name, type, access, default (node-relative COB-IDs resolved), limits and mapping
flag, and nothing else."""
from __future__ import annotations

import canopen
import pytest

from sea_hil.config.loader import load_config
from sea_hil.plant_emulator.cia402_drive import Cia402Limb
from sea_hil.protocol.cia402_eds import JOINTS, eds_path, eds_text
from sea_hil.protocol.cia402_od import ARRAY, RECORD, entries_by_key, joint_defaults, object_dictionary


@pytest.mark.parametrize("joint", range(2))
def test_shipped_eds_is_current(joint: int) -> None:
    text = eds_text(joint_defaults(load_config(), joint))
    assert eds_path(JOINTS[joint]).read_text(encoding="ascii") == text, "run python -m sea_hil.protocol.cia402_eds"


@pytest.mark.parametrize("joint,node_id", [(0, 1), (1, 2), (0, 17)])
def test_import_od_equals_the_drive_dictionary(joint: int, node_id: int) -> None:
    objs = object_dictionary(joint_defaults(load_config(), joint))
    od = canopen.objectdictionary.import_od(str(eds_path(JOINTS[joint])), node_id)
    assert sorted(od.keys()) == [o.index for o in objs]
    for o in objs:
        item = od[o.index]
        assert item.name == o.name
        if o.object_type in (ARRAY, RECORD):
            assert isinstance(item, canopen.objectdictionary.ODArray if o.object_type == ARRAY
                              else canopen.objectdictionary.ODRecord)
            assert sorted(item.subindices) == [e.subindex for e in o.entries]
        for e in o.entries:
            v = item[e.subindex] if o.object_type in (ARRAY, RECORD) else item
            got = (v.name, v.data_type, v.access_type, v.default, v.min, v.max, v.pdo_mappable)
            assert got == (e.name, e.data_type, e.access, e.default_for(node_id), e.low, e.high, e.pdo_mappable), \
                hex(e.index)


def test_the_running_drive_serves_that_dictionary() -> None:
    cfg = load_config(overrides={"can": {"profile": "cia402", "cia402": {"node_ids": [5, 6]}}})
    limb = Cia402Limb.create(cfg, (5, 6))
    limb.start(0)
    for a in limb.axes:
        entries = entries_by_key(object_dictionary(joint_defaults(cfg, a.joint)))
        od = canopen.objectdictionary.import_od(str(eds_path(JOINTS[a.joint])), a.slave.node_id)
        assert set(a.slave.values) == set(entries)
        for index, sub in entries:
            item = od[index]
            v = item[sub] if hasattr(item, "subindices") else item
            if index not in (0x6041, 0x6064, 0x2102, 0x2103, 0x606C, 0x2100, 0x2101):   # live values
                assert a.slave.values[(index, sub)] == v.default, hex(index)
