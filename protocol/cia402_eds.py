"""The EDS (CiA 306 electronic data sheet) of the emulated SEA drive, written from `protocol.cia402_od`: the text of
one joint's file and the shipped files' paths. `python -m sea_hil.protocol.cia402_eds [--config F] [--out DIR]`
regenerates them (the shipped ones come from the default configuration; tests/test_cia402_eds.py checks they are
current and that python canopen reads them as exactly the drive's dictionary)."""
from __future__ import annotations

import argparse
from pathlib import Path

from sea_hil.config.loader import load_config
from sea_hil.protocol.cia402_od import (
    ARRAY,
    DEVICE_TYPE,
    INTEGER8,
    INTEGER16,
    INTEGER32,
    PRODUCT_CODE,
    RECORD,
    REVISION,
    VENDOR_ID,
    VISIBLE_STRING,
    Entry,
    JointDefaults,
    Obj,
    joint_defaults,
    object_dictionary,
)

SIGNED = (INTEGER8, INTEGER16, INTEGER32)
JOINTS = ("hip", "knee")


def eds_path(joint: str) -> Path:
    """The shipped EDS of `joint` (package data of `sea_hil.protocol`)."""
    return Path(__file__).with_name(f"sea_cia402_{joint}.eds")


def _value(e: Entry, v: int | str) -> str:
    if e.data_type == VISIBLE_STRING:
        return str(v)
    if e.data_type in SIGNED:
        return str(int(v))
    return f"0x{int(v):X}"


def _entry_lines(section: str, e: Entry) -> list[str]:
    default = f"$NODEID+0x{int(e.default):X}" if e.node_relative else _value(e, e.default)
    lines = [f"[{section}]", f"ParameterName={e.name}", "ObjectType=0x7", f"DataType=0x{e.data_type:04X}",
             f"AccessType={e.access}", f"DefaultValue={default}", f"PDOMapping={int(e.pdo_mappable)}"]
    if e.low is not None:
        lines.append(f"LowLimit={_value(e, e.low)}")
    if e.high is not None:
        lines.append(f"HighLimit={_value(e, e.high)}")
    return lines + [""]


def _object_lines(o: Obj) -> list[str]:
    if o.object_type not in (ARRAY, RECORD):
        return _entry_lines(f"{o.index:04X}", o.entries[0])
    lines = [f"[{o.index:04X}]", f"ParameterName={o.name}", f"ObjectType=0x{o.object_type:X}",
             f"SubNumber=0x{len(o.entries):X}", ""]
    for e in o.entries:
        lines += _entry_lines(f"{o.index:04X}sub{e.subindex:X}", e)
    return lines


def eds_text(j: JointDefaults) -> str:
    """The EDS of one node with joint defaults `j` (deterministic: no dates, fixed order)."""
    objs = object_dictionary(j)
    mandatory = [o for o in objs if o.index in (0x1000, 0x1001, 0x1018)]
    optional = [o for o in objs if o not in mandatory and not 0x2000 <= o.index < 0x6000]
    manufacturer = [o for o in objs if 0x2000 <= o.index < 0x6000]
    lines = ["[FileInfo]", f"FileName=sea_cia402_{j.joint}.eds", "FileVersion=1", "FileRevision=0",
             "EDSVersion=4.0", f"Description=sea-hil emulated SEA drive, {j.joint} joint (CiA 301 / CiA 402)",
             "CreatedBy=sea-hil (protocol/cia402_od.py)", "",
             "[DeviceInfo]", "VendorName=sea-hil", f"VendorNumber=0x{VENDOR_ID:X}",
             f"ProductName=sea-hil SEA drive ({j.joint})", f"ProductNumber=0x{PRODUCT_CODE:X}",
             f"RevisionNumber=0x{REVISION:X}", "OrderCode=sea-hil",
             *(f"BaudRate_{r}={int(r == 1000)}" for r in (10, 20, 50, 125, 250, 500, 800, 1000)),
             "SimpleBootUpMaster=0", "SimpleBootUpSlave=1", "Granularity=8", "DynamicChannelsSupported=0",
             "GroupMessaging=0", "NrOfRXPDO=4", "NrOfTXPDO=4", "LSS_Supported=0", "",
             "[DummyUsage]", *(f"Dummy{i:04d}=0" for i in range(1, 8)), "",
             "[Comments]", "Lines=2",
             f"Line1=Device type 0x{DEVICE_TYPE:08X}; units and default PDO set: docs/cia402.md",
             "Line2=Generated from the default configuration; regenerate with python -m sea_hil.protocol.cia402_eds",
             ""]
    for title, group in (("MandatoryObjects", mandatory), ("OptionalObjects", optional),
                         ("ManufacturerObjects", manufacturer)):
        lines += [f"[{title}]", f"SupportedObjects={len(group)}",
                  *(f"{i + 1}=0x{o.index:04X}" for i, o in enumerate(group)), ""]
        for o in group:
            lines += _object_lines(o)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="write the hip and knee EDS files of the CiA 402 profile")
    ap.add_argument("--config", help="TOML overlay (default: the embedded default configuration)")
    ap.add_argument("--out", type=Path, help="directory (default: the package's own files)")
    args = ap.parse_args(argv)
    cfg = load_config(args.config)
    for joint, name in enumerate(JOINTS):
        path = (args.out / eds_path(name).name) if args.out else eds_path(name)
        path.write_text(eds_text(joint_defaults(cfg, joint)), encoding="ascii")
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
