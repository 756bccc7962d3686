"""Laser altimetry of real missions, read and written: OSIRIS-REx OLA Level 2 (a PDS4 binary
table described by its XML label) and Hayabusa2 LIDAR Level 2 (CSV).

Both products give, per laser shot, its time, the measured range, the footprint in the
target's body-fixed frame and the spacecraft position in the same frame; recon reads them into
an :class:`Altimetry` (metres, seconds of ET) that ``recon ingest`` turns into a body-frame
cloud.

**OLA Level 2** (OSIRIS-REx Laser Altimeter, calibrated science data; layout of the published
example label ``sci_l2_product`` of the ``orex.ola`` PDS4 bundle and the OLA SIS): one record of
186 bytes per sample, 23 fields (``met``, ``met_offset``, ``utc``, ``et``, ``scan_ola_time``,
``power_cycle``, ``laser_selection``, ``scan_mode``, ``flag_status``, ``range`` [mm],
``azimuth``, ``elevation`` [mrad], ``intensity_t0``, ``intensity_trr``, ``x``, ``y``, ``z`` [m],
``elongitude``, ``latitude`` [deg], ``radius`` [km], ``scx``, ``scy``, ``scz`` [m]). Nothing
of that layout is fixed here: every field's name, byte location, length, data type (and so
endianness), unit, ``scaling_factor`` and ``value_offset`` are read from the label's
``Table_Binary``/``Record_Binary``/``Field_Binary`` elements, and fields are found by name.
``flag_status`` codes (0 valid return, 1 valid return with overflow, 2 no return, 3 missing
sample; 100-103 the same with the demodulator on): only valid returns without overflow (0 and
100) are kept; the others are dropped and counted by reason.

**Hayabusa2 LIDAR Level 2** (time-series topography; column list of the product description of
the Hayabusa2 LIDAR bundle, ``browse/topo_ts``): comma-separated, one line per shot, columns
``SHOT_TIME`` (UTC), ``RANGE``, ``TOPO_LONGITUDE``, ``TOPO_LATITUDE`` [deg], ``TOPO_HEIGHT``,
``TOPO_X``, ``TOPO_Y``, ``TOPO_Z``, ``SC_POS_X``, ``SC_POS_Y``, ``SC_POS_Z``, lengths in metres
as the product description states. A first line of column names is read when present (any
order; a unit after a name, ``RANGE [km]`` or ``RANGE(km)``, is honoured); without one the
columns are taken in the published order. Lines whose values are missing or not numbers are
dropped and counted.

Files are taken as hostile: sizes declared by a label are checked against the file before
anything is read, names may not leave the label's directory, and every problem is one
:class:`InputError` line naming the file and the field.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from formats.atomic import write_atomically
from formats.errors import InputError
from formats.paths import check_source

# Largest label read [bytes]: a PDS4 label of a table is tens of kB.
MAX_LABEL_BYTES = 4 << 20
# Largest CSV product read [bytes]: a day of Hayabusa2 LIDAR shots at 1 Hz is ~15 MB.
MAX_CSV_BYTES = 2 << 30
METRES_PER = {"mm": 1e-3, "millimeter": 1e-3, "millimeters": 1e-3, "m": 1.0, "meter": 1.0,
              "meters": 1.0, "metre": 1.0, "metres": 1.0, "km": 1e3, "kilometer": 1e3,
              "kilometers": 1e3}
SECONDS_PER = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0}
RADIANS_PER = {"rad": 1.0, "mrad": 1e-3, "deg": math.pi / 180.0, "degree": math.pi / 180.0,
               "degrees": math.pi / 180.0}
# PDS4 binary data types (PDS4 Standards Reference, Binary field types) as numpy dtypes.
PDS4_BINARY_TYPES = {
    "IEEE754LSBDouble": "<f8", "IEEE754MSBDouble": ">f8",
    "IEEE754LSBSingle": "<f4", "IEEE754MSBSingle": ">f4",
    "SignedByte": "i1", "UnsignedByte": "u1",
    "SignedLSB2": "<i2", "SignedMSB2": ">i2", "UnsignedLSB2": "<u2", "UnsignedMSB2": ">u2",
    "SignedLSB4": "<i4", "SignedMSB4": ">i4", "UnsignedLSB4": "<u4", "UnsignedMSB4": ">u4",
    "SignedLSB8": "<i8", "SignedMSB8": ">i8", "UnsignedLSB8": "<u8", "UnsignedMSB8": ">u8",
}
PDS4_STRING_TYPES = ("ASCII_String", "UTF8_String", "ASCII_Date_Time_DOY",
                     "ASCII_Date_Time_YMD", "ASCII_Date_Time_UTC")
# OLA flag_status: the code modulo 100 (100-103 repeat 0-3 with the demodulator on).
OLA_FLAGS = {0: "valid return", 1: "valid return with overflow", 2: "no return",
             3: "missing sample"}
OLA_KEPT_FLAGS = (0,)
HAYABUSA2_COLUMNS = ("SHOT_TIME", "RANGE", "TOPO_LONGITUDE", "TOPO_LATITUDE", "TOPO_HEIGHT",
                     "TOPO_X", "TOPO_Y", "TOPO_Z", "SC_POS_X", "SC_POS_Y", "SC_POS_Z")
HAYABUSA2_LENGTHS = ("RANGE", "TOPO_HEIGHT", "TOPO_X", "TOPO_Y", "TOPO_Z", "SC_POS_X",
                     "SC_POS_Y", "SC_POS_Z")


@dataclass
class Altimetry:
    """The returns of an altimetry product, in SI units and the target's body-fixed frame.

    Attributes
    ----------
    et : (n,) float64, seconds TDB past J2000
    range : (n,) float64, metres
    points : (n, 3) float64, metres, target body-fixed frame
    spacecraft : (n, 3) float64 metres, same frame, or None when the product has none
    record : (n,) int64, row of each return in the product
    dropped : dict of str to int
        Rows not kept, by reason (flags, missing values).
    product : str
        ``ola-l2`` or ``hayabusa2-lidar-l2``.
    source : str
        The file read.
    """

    et: np.ndarray
    range: np.ndarray
    points: np.ndarray
    spacecraft: np.ndarray | None
    record: np.ndarray
    dropped: dict = field(default_factory=dict)
    product: str = ""
    source: str = ""

    def __post_init__(self):
        """Refuse returns no sensor could make: a range that is not finite and positive, a
        coordinate beyond ``MAX_COORDINATE_M`` (naming the file and the product's row)."""
        from formats.geometry import check_extent

        bad = np.flatnonzero(~(np.isfinite(self.range) & (self.range > 0)))
        if len(bad):
            raise InputError(f"{self.source}: row {self.record[bad[0]] + 1}: range "
                             f"{self.range[bad[0]]:g} m is not a positive distance "
                             f"({len(bad)} such row(s))")
        check_extent(self.points, f"{self.source}: points")
        if self.spacecraft is not None:
            check_extent(self.spacecraft, f"{self.source}: spacecraft positions")

    def __len__(self) -> int:
        return len(self.et)


# --------------------------------------------------------------------------- PDS4 labels


def _local(tag: str) -> str:
    """An element's name without its XML namespace."""
    return tag.rsplit("}", 1)[-1]


def _child(element, name: str):
    return next((c for c in element if _local(c.tag) == name), None)


def _text(element, name: str, where: str) -> str:
    child = _child(element, name)
    if child is None or child.text is None or not child.text.strip():
        raise InputError(f"{where}: no <{name}>")
    return child.text.strip()


def _count(element, name: str, where: str, *, minimum: int = 0) -> int:
    text = _text(element, name, where)
    try:
        value = int(text)
    except ValueError:
        raise InputError(f"{where}: <{name}> must be an integer, got {text[:40]!r}") from None
    if value < minimum:
        raise InputError(f"{where}: <{name}> must be at least {minimum}, got {value}")
    return value


def _number(element, name: str, where: str, default: float) -> float:
    child = _child(element, name)
    if child is None or child.text is None:
        return default
    try:
        value = float(child.text)
    except ValueError:
        raise InputError(f"{where}: <{name}> must be a number, got "
                             f"{child.text.strip()[:40]!r}") from None
    if not math.isfinite(value):
        raise InputError(f"{where}: <{name}> must be finite, got {value!r}")
    return value


@dataclass(frozen=True)
class BinaryField:
    """One ``Field_Binary`` of a PDS4 label: where it is and how to read it."""

    name: str
    location: int      # 1-based byte in the record
    length: int        # bytes
    data_type: str
    unit: str
    scaling_factor: float
    value_offset: float

    @property
    def dtype(self) -> np.dtype:
        if self.data_type in PDS4_STRING_TYPES:
            return np.dtype(f"S{self.length}")
        return np.dtype(PDS4_BINARY_TYPES[self.data_type])


@dataclass(frozen=True)
class BinaryTable:
    """A PDS4 ``Table_Binary`` as its label declares it."""

    data: Path
    offset: int
    records: int
    record_length: int
    fields: dict      # lower-case name -> BinaryField

    def field(self, *names: str, where: str) -> BinaryField:
        """The first field named one of ``names`` (case-insensitive)."""
        for name in names:
            if name.lower() in self.fields:
                return self.fields[name.lower()]
        raise InputError(f"{where}: the table has no field {' or '.join(names)}")

    def optional(self, *names: str) -> BinaryField | None:
        return next((self.fields[n.lower()] for n in names if n.lower() in self.fields), None)


def _label_root(label: Path) -> ElementTree.Element:
    """The parsed XML of a label no larger than MAX_LABEL_BYTES, without DOCTYPE or entities."""
    where = str(label)
    size = label.stat().st_size
    if size > MAX_LABEL_BYTES:
        raise InputError(f"{where}: {size:,} bytes, larger than any PDS4 label "
                             f"({MAX_LABEL_BYTES:,} at most)")
    raw = label.read_bytes()
    if b"<!DOCTYPE" in raw or b"<!ENTITY" in raw:
        raise InputError(f"{where}: a PDS4 label declares no DOCTYPE or entities")
    try:
        return ElementTree.fromstring(raw)
    except ElementTree.ParseError as exc:
        raise InputError(f"{where}: not an XML label ({exc})") from None


def _required(parent: ElementTree.Element, name: str, within: str, where: str
              ) -> ElementTree.Element:
    """The child ``<name>`` of ``parent`` (the element ``<within>``), or InputError."""
    child = _child(parent, name)
    if child is None:
        raise InputError(f"{where}: no <{name}> in <{within}>")
    return child


def _data_file(label: Path, area: ElementTree.Element) -> Path:
    """The data file ``<File>/<file_name>`` names, which must lie beside the label."""
    where = str(label)
    name = _text(_required(area, "File", "File_Area_Observational", where), "file_name", where)
    if Path(name).name != name or name in (".", ".."):
        raise InputError(f"{where}: <file_name> {name[:80]!r} must name a file beside the "
                             "label")
    data = check_source(label.parent / name, InputError)
    if data.resolve().parent != label.parent.resolve():   # a symbolic link out of the directory
        raise InputError(f"{where}: <file_name> {name[:80]!r} leads out of the label's "
                         f"directory (to {data.resolve()}); copy the table beside the label")
    return data


def _binary_field(element: ElementTree.Element, record_length: int, where: str) -> BinaryField:
    """One ``<Field_Binary>``, checked: known type, its length, inside the record."""
    name = _text(element, "name", where)
    at = f"{where}: field {name[:60]!r}"
    unit = _child(element, "unit")
    fld = BinaryField(name=name, location=_count(element, "field_location", at, minimum=1),
                      length=_count(element, "field_length", at, minimum=1),
                      data_type=_text(element, "data_type", at),
                      unit=(unit.text or "").strip() if unit is not None else "",
                      scaling_factor=_number(element, "scaling_factor", at, 1.0),
                      value_offset=_number(element, "value_offset", at, 0.0))
    if fld.data_type not in PDS4_BINARY_TYPES and fld.data_type not in PDS4_STRING_TYPES:
        raise InputError(f"{at}: unknown data_type {fld.data_type[:40]!r}")
    if fld.dtype.itemsize != fld.length:
        raise InputError(f"{at}: {fld.data_type} has {fld.dtype.itemsize} bytes, the "
                             f"label says field_length {fld.length}")
    if fld.location + fld.length - 1 > record_length:
        raise InputError(f"{at}: bytes {fld.location}..{fld.location + fld.length - 1} "
                             f"lie outside the {record_length}-byte record")
    return fld


def _binary_fields(record: ElementTree.Element, record_length: int, where: str
                   ) -> dict[str, BinaryField]:
    """The ``<Field_Binary>`` of a ``<Record_Binary>`` by lower-case name, as many as its
    ``<fields>`` declares, none named twice."""
    if _count(record, "groups", where) != 0:
        raise InputError(f"{where}: <Group_Field_Binary> (groups > 0) is not supported")
    fields: dict[str, BinaryField] = {}
    for element in record:
        if _local(element.tag) != "Field_Binary":
            continue
        fld = _binary_field(element, record_length, where)
        if fld.name.lower() in fields:
            raise InputError(f"{where}: field {fld.name[:60]!r}: named twice")
        fields[fld.name.lower()] = fld
    declared = _count(record, "fields", where)
    if declared != len(fields):
        raise InputError(f"{where}: <fields> says {declared}, the record has {len(fields)} "
                             "<Field_Binary>")
    return fields


def read_label(label) -> BinaryTable:
    """Parse the first ``Table_Binary`` of a PDS4 label and check it against its data file.

    Raises
    ------
    InputError
        The label is not XML, declares an entity, lacks an element, names a data file outside
        its directory or one shorter than ``offset + records * record_length``, or a field that
        lies outside the record or has an unknown data type or a length its type does not have.
    """
    label = check_source(label, InputError)
    where = str(label)
    root = _label_root(label)
    area = next((e for e in root.iter() if _local(e.tag) == "File_Area_Observational"), None)
    if area is None:
        raise InputError(f"{where}: no <File_Area_Observational>")
    data = _data_file(label, area)
    table = _required(area, "Table_Binary", "File_Area_Observational", where)
    offset = _count(table, "offset", where)
    records = _count(table, "records", where)
    record = _required(table, "Record_Binary", "Table_Binary", where)
    record_length = _count(record, "record_length", where, minimum=1)
    fields = _binary_fields(record, record_length, where)
    need = offset + records * record_length
    have = data.stat().st_size
    if have < need:
        raise InputError(f"{data}: {have:,} bytes, but its label {label.name} declares "
                             f"{records:,} records of {record_length} bytes from byte {offset} "
                             f"({need:,} bytes)")
    return BinaryTable(data=data, offset=offset, records=records, record_length=record_length,
                       fields=fields)


def read_columns(table: BinaryTable, fields: list[BinaryField]) -> dict[str, np.ndarray]:
    """The values of ``fields`` for every record, scaled (``value * scaling_factor +
    value_offset``) for numbers; strings as ``bytes`` arrays. Keyed by field name."""
    if table.records == 0:
        return {f.name: np.zeros(0, f.dtype if f.dtype.kind == "S" else np.float64)
                for f in fields}
    dtype = np.dtype({"names": [f.name for f in fields], "formats": [f.dtype for f in fields],
                      "offsets": [f.location - 1 for f in fields],
                      "itemsize": table.record_length})
    rows = np.memmap(table.data, dtype=dtype, mode="r", offset=table.offset,
                     shape=(table.records,))
    out = {}
    for f in fields:
        values = np.array(rows[f.name])
        if values.dtype.kind != "S":
            values = values.astype(np.float64) * f.scaling_factor + f.value_offset
        out[f.name] = values
    del rows
    return out


def _scale(fld: BinaryField, table: BinaryTable, units: dict, what: str) -> float:
    factor = units.get(fld.unit.lower())
    if factor is None:
        raise InputError(f"{table.data}: field {fld.name!r} has unit {fld.unit!r}, not a "
                             f"{what} unit ({', '.join(sorted(units))})")
    return factor


# --------------------------------------------------------------------------- OLA Level 2


def _ola_fields(table: BinaryTable, where: str) -> dict:
    """The OLA fields a reading needs: ``range``, ``flag``, ``xyz`` (3), ``time`` and ``sc``
    (3 spacecraft-position fields, or None when the table has none); every one but ``time``
    numeric."""
    sc = [table.optional(n, f"sc_{n[-1]}", f"sc_pos_{n[-1]}") for n in ("scx", "scy", "scz")]
    fields = {"range": table.field("range", where=where),
              "flag": table.field("flag_status", where=where),
              "xyz": [table.field(axis, where=where) for axis in ("x", "y", "z")],
              "time": table.optional("et") or table.field("et", "utc", where=where),
              "sc": sc if all(s is not None for s in sc) else None}
    for fld in (fields["range"], fields["flag"], *fields["xyz"], *(fields["sc"] or [])):
        if fld.dtype.kind == "S":
            raise InputError(f"{where}: field {fld.name!r} is {fld.data_type}, expected a "
                                 "number")
    return fields


def _ola_kept(flags: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
    """Which rows ``flag_status`` keeps (n,) bool, and the others counted by reason."""
    code = flags.astype(np.int64) % 100
    keep = np.isin(code, OLA_KEPT_FLAGS)
    dropped: dict[str, int] = {}
    for value, count in zip(*np.unique(code[~keep], return_counts=True), strict=True):
        reason = OLA_FLAGS.get(int(value), f"flag_status {int(value)}")
        dropped[reason] = int(count)
    return keep, dropped


def _ola_et(table: BinaryTable, time: BinaryField, values: np.ndarray, keep: np.ndarray,
            where: str) -> np.ndarray:
    """ET [s] of each record from an ``et`` number or a ``utc`` text (NaN where not kept)."""
    from formats.errors import InputError
    from formats.spice import utcs_to_et

    if time.dtype.kind != "S":
        return values * _scale(time, table, SECONDS_PER, "time")
    texts = [t.decode("ascii", "replace").strip() for t in values[keep]]
    et = np.full(table.records, np.nan)
    try:
        et[keep] = utcs_to_et(texts, f"{where}: field {time.name!r}")
    except InputError as exc:
        raise InputError(str(exc)) from None
    return et


def read_ola_l2(label) -> Altimetry:
    """Read an OLA Level-2 table through its PDS4 label (see the module docstring).

    Parameters
    ----------
    label : str or Path
        The ``.xml`` label; its ``<file_name>`` names the table beside it.

    Returns
    -------
    Altimetry
        Kept returns; ``dropped`` counts the others by ``flag_status`` reason (and rows whose
        values are not finite).
    """
    table = read_label(label)
    where = str(label)
    f = _ola_fields(table, where)
    rng, xyz, time, sc = f["range"], f["xyz"], f["time"], f["sc"]
    columns = read_columns(table, [rng, f["flag"], *xyz, time, *(sc or [])])
    keep, dropped = _ola_kept(columns[f["flag"].name])

    def metres(fields: list[BinaryField]) -> np.ndarray:
        return np.column_stack([columns[g.name] * _scale(g, table, METRES_PER, "length")
                                for g in fields])

    ranges = metres([rng])[:, 0]
    points = metres(xyz)
    spacecraft = metres(sc) if sc is not None else None
    et = _ola_et(table, time, columns[time.name], keep, where)
    finite = np.isfinite(ranges) & np.isfinite(points).all(axis=1) & np.isfinite(et)
    if spacecraft is not None:
        finite &= np.isfinite(spacecraft).all(axis=1)
    if (keep & ~finite).any():
        dropped["values not finite"] = int((keep & ~finite).sum())
    keep &= finite
    return Altimetry(et=et[keep], range=ranges[keep], points=points[keep],
                     spacecraft=None if spacecraft is None else spacecraft[keep],
                     record=np.flatnonzero(keep), dropped=dropped, product="ola-l2",
                     source=str(label))


def ola_fields() -> list[tuple[str, str, int, str, str, str]]:
    """The OLA Level-2 record as recon writes it: (name, data type, length, format, unit,
    description) in order, 186 bytes, the published layout (module docstring)."""
    d, i2, text = "IEEE754LSBDouble", "SignedLSB2", "ASCII_String"
    return [
        ("met", text, 18, "%18s", "s/c_ticks", "Spacecraft clock time (recon's clock -999: "
         "seconds/ticks of 1/65536 s)"),
        ("met_offset", d, 8, "%14.5e", "s/c_ticks", "Ticks (2^-16 s) to add to met for the "
         "precise time"),
        ("utc", text, 24, "%24s", "", "UTC Time (yyyy-doyThh:mm:ss.ssssss)"),
        ("et", d, 8, "%14.5e", "s", "Ephemeris time"),
        ("scan_ola_time", d, 8, "%14.5e", "s", "Time tag of this record (recon: time since the "
         "start of the campaign)"),
        ("power_cycle", i2, 2, "%6d", "", "Power Cycle counter"),
        ("laser_selection", i2, 2, "%6d", "", "High Energy (0) or Low Energy Laser (1)"),
        ("scan_mode", i2, 2, "%6d", "", "Selected Scan Pattern (0: Raster, 1: Linear, 2: "
         "Fixed)"),
        ("flag_status", i2, 2, "%6d", "", "Status of return. (0: valid return, 1: valid return "
         "with overflow, 2: no return, 3: missing sample)"),
        ("range", d, 8, "%14.5e", "mm", "Range from the instrument to the surface"),
        ("azimuth", d, 8, "%14.5e", "mrad", "Scan azimuth of the return in the instrument "
         "frame"),
        ("elevation", d, 8, "%14.5e", "mrad", "Scan elevation of the return in the instrument "
         "frame"),
        ("intensity_t0", d, 8, "%14.5e", "DN", "Outgoing pulse intensity (not simulated: 0)"),
        ("intensity_trr", d, 8, "%14.5e", "DN", "Return pulse intensity (not simulated: 0)"),
        ("x", d, 8, "%14.5e", "m", "X of the return in the target body-fixed frame"),
        ("y", d, 8, "%14.5e", "m", "Y of the return in the target body-fixed frame"),
        ("z", d, 8, "%14.5e", "m", "Z of the return in the target body-fixed frame"),
        ("elongitude", d, 8, "%14.5e", "deg", "East longitude of the return"),
        ("latitude", d, 8, "%14.5e", "deg", "Latitude of the return"),
        ("radius", d, 8, "%14.5e", "km", "Distance of the return from the target centre"),
        ("scx", d, 8, "%14.5e", "m", "X of the spacecraft in the target body-fixed frame"),
        ("scy", d, 8, "%14.5e", "m", "Y of the spacecraft in the target body-fixed frame"),
        ("scz", d, 8, "%14.5e", "m", "Z of the spacecraft in the target body-fixed frame"),
    ]


def _escape(text: str) -> str:
    return (text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;"))


def ola_label(data_name: str, records: int, *, start_utc: str, stop_utc: str,
              title: str) -> str:
    """The PDS4 label of an OLA Level-2 table written by recon."""
    specs = ola_fields()
    record_length = sum(s[2] for s in specs)
    fields, location = [], 1
    for number, (name, dtype, length, fmt, unit, description) in enumerate(specs, start=1):
        unit_xml = f"\n          <unit>{_escape(unit)}</unit>" if unit else ""
        fields.append(f"""        <Field_Binary>
          <name>{name}</name>
          <field_number>{number}</field_number>
          <field_location unit="byte">{location}</field_location>
          <data_type>{dtype}</data_type>
          <field_length unit="byte">{length}</field_length>
          <field_format>{fmt}</field_format>{unit_xml}
          <description>{_escape(description)}</description>
        </Field_Binary>""")
        location += length
    body = "\n".join(fields)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<Product_Observational xmlns="http://pds.nasa.gov/pds4/pds/v1">
  <Identification_Area>
    <logical_identifier>urn:recon:simulated:ola_l2:{_escape(data_name.lower())}</logical_identifier>
    <version_id>1.0</version_id>
    <title>{_escape(title)}</title>
    <information_model_version>1.7.0.0</information_model_version>
    <product_class>Product_Observational</product_class>
  </Identification_Area>
  <Observation_Area>
    <Time_Coordinates>
      <start_date_time>{start_utc}Z</start_date_time>
      <stop_date_time>{stop_utc}Z</stop_date_time>
    </Time_Coordinates>
  </Observation_Area>
  <File_Area_Observational>
    <File>
      <file_name>{_escape(data_name)}</file_name>
      <file_size unit="byte">{records * record_length}</file_size>
    </File>
    <Table_Binary>
      <offset unit="byte">0</offset>
      <records>{records}</records>
      <Record_Binary>
        <fields>{len(specs)}</fields>
        <groups>0</groups>
        <record_length unit="byte">{record_length}</record_length>
{body}
      </Record_Binary>
    </Table_Binary>
  </File_Area_Observational>
</Product_Observational>
"""


def ola_records(columns: dict[str, np.ndarray]) -> np.ndarray:
    """Records of the OLA Level-2 layout (:func:`ola_fields`) from columns in the label's units
    (``met``/``utc`` as bytes); a column not given is 0."""
    specs = ola_fields()
    n = len(next(iter(columns.values())))
    dtype = np.dtype([(name, f"S{length}" if kind == "ASCII_String" else
                       PDS4_BINARY_TYPES[kind]) for name, kind, length, *_ in specs])
    records = np.zeros(n, dtype=dtype)
    for name, values in columns.items():
        records[name] = values
    return records


def write_ola_l2(label, columns: dict[str, np.ndarray], *, title: str) -> tuple[Path, Path]:
    """Write an OLA Level-2 table (``LABEL`` with ``.dat``) and its PDS4 label, atomically.

    Parameters
    ----------
    label : str or Path
        The ``.xml`` label to write; the table is written beside it with suffix ``.dat``.
    columns : dict of field name -> (n,) array, in the label's units (:func:`ola_fields`)
    title : str
        The label's title.

    Returns
    -------
    (label path, table path)
    """
    label = Path(label)
    if label.suffix.lower() != ".xml":
        raise InputError(f"{label}: an OLA Level-2 product is written as its .xml label")
    data = label.with_suffix(".dat")
    records = ola_records(columns)
    utc = [u.decode() for u in records["utc"][[0, -1]]] if len(records) else ["", ""]
    write_atomically(data, records.tofile, error=InputError)
    text = ola_label(data.name, len(records), start_utc=_isoc(utc[0]), stop_utc=_isoc(utc[1]),
                     title=title)
    write_atomically(label, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"),
                     error=InputError)
    return label, data


def _isoc(doy: str) -> str:
    """``2019-044T01:01:01.796000`` -> ``2019-02-13T01:01:01.796000`` (PDS4 dates are
    calendar dates in labels)."""
    if not doy:
        return "2000-01-01T12:00:00"
    import datetime

    date, _, clock = doy.partition("T")
    year, day = date.split("-")
    calendar = datetime.date(int(year), 1, 1) + datetime.timedelta(days=int(day) - 1)
    return f"{calendar.isoformat()}T{clock}"


# --------------------------------------------------------------------------- Hayabusa2 LIDAR L2

_HEADER_UNIT = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(?:[\[(]\s*([A-Za-z]+)\s*[\])])?\s*$")


def _header(first: list[str], where: str) -> tuple[list[str], dict[str, float]] | None:
    """Column names and length scales of a header line, or None when it is a data line."""
    matches = [_HEADER_UNIT.match(cell) for cell in first]
    if not all(matches):
        return None
    names = [m.group(1).upper() for m in matches]
    missing = [c for c in HAYABUSA2_COLUMNS if c not in names]
    if missing:
        raise InputError(f"{where}: header has no column {', '.join(missing)}")
    scales = {}
    for m in matches:
        name, unit = m.group(1).upper(), (m.group(2) or "m").lower()
        if name in HAYABUSA2_LENGTHS:
            if unit not in METRES_PER:
                raise InputError(f"{where}: column {name} has unit {unit!r}, not a length "
                                     "unit (mm, m, km)")
            scales[name] = METRES_PER[unit]
    return names, scales


def _csv_rows(path: Path) -> list[tuple[int, list[str]]]:
    """The CSV's non-blank, non-comment lines as (line number, cells); at least one."""
    where = str(path)
    size = path.stat().st_size
    if size > MAX_CSV_BYTES:
        raise InputError(f"{where}: {size:,} bytes, larger than this reader takes "
                             f"({MAX_CSV_BYTES:,})")
    try:
        lines = path.read_text(encoding="ascii").splitlines()
    except UnicodeDecodeError as exc:
        raise InputError(f"{where}: not an ASCII CSV ({exc.reason} at byte "
                             f"{exc.start})") from None
    rows = [(number, line.split(",")) for number, line in enumerate(lines, start=1)
            if line.strip() and not line.lstrip().startswith("#")]
    if not rows:
        raise InputError(f"{where}: no lines")
    return rows


def _hayabusa2_values(rows, names: list[str], scales: dict[str, float], where: str
                      ) -> tuple[list[str], list[list[float]], list[int], int]:
    """Shot times, numeric values (metres) and line numbers of the lines with every needed
    value, and how many lines lacked one."""
    index = {name: names.index(name) for name in HAYABUSA2_COLUMNS}
    numeric = [c for c in HAYABUSA2_COLUMNS if c in HAYABUSA2_LENGTHS]
    times, values, numbers, missing = [], [], [], 0
    for number, cells in rows:
        if len(cells) != len(names):
            raise InputError(f"{where}: line {number} has {len(cells)} values, expected "
                                 f"{len(names)} ({', '.join(names[:3])}, ...)")
        try:
            row = [float(cells[index[c]]) * scales[c] for c in numeric]
        except ValueError:
            row = None
        time = cells[index["SHOT_TIME"]].strip()
        if row is None or not time or not all(map(math.isfinite, row)):
            missing += 1
            continue
        times.append(time)
        values.append(row)
        numbers.append(number)
    return times, values, numbers, missing


def read_hayabusa2_l2(path) -> Altimetry:
    """Read a Hayabusa2 LIDAR Level-2 CSV (see the module docstring).

    Returns
    -------
    Altimetry
        Lines with every needed value; ``dropped`` counts those with a missing value.
    """
    from formats.errors import InputError
    from formats.spice import utcs_to_et

    path = check_source(path, InputError)
    where = str(path)
    rows = _csv_rows(path)
    header = _header(rows[0][1], where)
    names, scales = header or (list(HAYABUSA2_COLUMNS), dict.fromkeys(HAYABUSA2_LENGTHS, 1.0))
    times, values, numbers, missing = _hayabusa2_values(rows[1:] if header else rows, names,
                                                        scales, where)
    try:
        et = utcs_to_et(times, f"{where}: SHOT_TIME")
    except InputError as exc:
        raise InputError(str(exc)) from None
    numeric = [c for c in HAYABUSA2_COLUMNS if c in HAYABUSA2_LENGTHS]
    table = np.array(values, dtype=np.float64).reshape(-1, len(numeric))
    col = {c: table[:, k] for k, c in enumerate(numeric)}
    return Altimetry(et=et, range=col["RANGE"],
                     points=np.column_stack([col["TOPO_X"], col["TOPO_Y"], col["TOPO_Z"]]),
                     spacecraft=np.column_stack([col["SC_POS_X"], col["SC_POS_Y"],
                                                 col["SC_POS_Z"]]),
                     record=np.array(numbers, dtype=np.int64) - 1,
                     dropped={"missing values": missing} if missing else {},
                     product="hayabusa2-lidar-l2", source=where)


def write_hayabusa2_l2(path, *, utc: list[str], range_m: np.ndarray, points: np.ndarray,
                       spacecraft: np.ndarray) -> Path:
    """Write a Hayabusa2 LIDAR Level-2 CSV in the published column order (no header line,
    metres and degrees), atomically.

    Parameters
    ----------
    path : str or Path
    utc : list of str, UTC of each shot (``YYYY-MM-DDTHH:MM:SS.ffffff``)
    range_m : (n,) float64, metres
    points, spacecraft : (n, 3) float64, metres, target body-fixed frame
    """
    radius = np.linalg.norm(points, axis=1)
    longitude = np.degrees(np.arctan2(points[:, 1], points[:, 0])) % 360.0
    latitude = np.degrees(np.arcsin(np.clip(points[:, 2] / np.where(radius > 0, radius, 1.0),
                                            -1.0, 1.0)))
    numbers = np.column_stack([range_m, longitude, latitude, radius, points, spacecraft])
    text = "".join(f"{t}," + ",".join(f"{v:.6f}" for v in row) + "\n"
                   for t, row in zip(utc, numbers, strict=True))
    return write_atomically(path, lambda tmp: Path(tmp).write_text(text, encoding="ascii"),
                            error=InputError)
