"""Readers of real altimetry products, on small files written here to the published layouts.

- OSIRIS-REx OLA Level 2: the 23-field, 186-byte record of the example label ``sci_l2_product``
  in the ``orex.ola`` PDS4 bundle's document collection (fields 1-10: met, met_offset, utc, et,
  scan_ola_time, power_cycle, laser_selection, scan_mode, flag_status, range [mm], at bytes 1,
  19, 27, 51, 59, 67, 69, 71, 73, 75); fields 11-23 (azimuth, elevation, intensity_t0,
  intensity_trr, x, y, z [m] at bytes 115, 123, 131, elongitude, latitude, radius, scx, scy,
  scz) as the OLA SIS's calibrated (``data_calibrated_v2``) labels give them, flag_status codes
  0 valid return, 1 valid with overflow, 2 no return, 3 missing sample, 100-103 the same with
  the demodulator on.
- Hayabusa2 LIDAR Level 2: the column list of the time-series topography product description
  (Hayabusa2 LIDAR bundle, ``browse/topo_ts``): SHOT_TIME (UTC), RANGE, TOPO_LONGITUDE,
  TOPO_LATITUDE, TOPO_HEIGHT, TOPO_X, TOPO_Y, TOPO_Z, SC_POS_X, SC_POS_Y, SC_POS_Z, lengths in
  m; comma-separated without a header line, as the Small Body Mapping Tool reads it.
"""

from __future__ import annotations

import numpy as np
import pytest

from formats import spice
from formats.altimetry import read_hayabusa2_l2, read_label, read_ola_l2
from formats.errors import InputError

# (name, PDS4 data type, bytes, unit) in the published order.
OLA_LAYOUT = [
    ("met", "ASCII_String", 18, ""), ("met_offset", "IEEE754LSBDouble", 8, "s/c_ticks"),
    ("utc", "ASCII_String", 24, ""), ("et", "IEEE754LSBDouble", 8, "s"),
    ("scan_ola_time", "IEEE754LSBDouble", 8, "s"), ("power_cycle", "SignedLSB2", 2, ""),
    ("laser_selection", "SignedLSB2", 2, ""), ("scan_mode", "SignedLSB2", 2, ""),
    ("flag_status", "SignedLSB2", 2, ""), ("range", "IEEE754LSBDouble", 8, "mm"),
    ("azimuth", "IEEE754LSBDouble", 8, "mrad"), ("elevation", "IEEE754LSBDouble", 8, "mrad"),
    ("intensity_t0", "IEEE754LSBDouble", 8, "DN"), ("intensity_trr", "IEEE754LSBDouble", 8, "DN"),
    ("x", "IEEE754LSBDouble", 8, "m"), ("y", "IEEE754LSBDouble", 8, "m"),
    ("z", "IEEE754LSBDouble", 8, "m"), ("elongitude", "IEEE754LSBDouble", 8, "deg"),
    ("latitude", "IEEE754LSBDouble", 8, "deg"), ("radius", "IEEE754LSBDouble", 8, "km"),
    ("scx", "IEEE754LSBDouble", 8, "m"), ("scy", "IEEE754LSBDouble", 8, "m"),
    ("scz", "IEEE754LSBDouble", 8, "m"),
]
NUMPY = {"ASCII_String": "S", "IEEE754LSBDouble": "<f8", "IEEE754MSBDouble": ">f8",
         "SignedLSB2": "<i2", "SignedMSB2": ">i2", "IEEE754MSBSingle": ">f4"}
FLAGS = [0, 1, 2, 3, 100, 0, 102, 0]   # kept: rows 0, 4, 5, 7


def _label(data_name: str, records: int, layout, *, offset: int = 0, extra: str = "",
           scaling: dict | None = None) -> str:
    """A PDS4 label as the archive writes it (namespaced, with units on byte counts)."""
    fields, location = [], 1
    for number, (name, dtype, length, unit) in enumerate(layout, start=1):
        scale = ""
        if scaling and name in scaling:
            scale = (f"<scaling_factor>{scaling[name][0]}</scaling_factor>"
                     f"<value_offset>{scaling[name][1]}</value_offset>")
        fields.append(f"<Field_Binary><name>{name}</name><field_number>{number}</field_number>"
                      f"<field_location unit=\"byte\">{location}</field_location>"
                      f"<data_type>{dtype}</data_type>"
                      f"<field_length unit=\"byte\">{length}</field_length>"
                      + (f"<unit>{unit}</unit>" if unit else "") + scale
                      + "<description>test</description></Field_Binary>")
        location += length
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n'
            f'<Product_Observational xmlns="http://pds.nasa.gov/pds4/pds/v1">{extra}'
            f"<File_Area_Observational><File><file_name>{data_name}</file_name></File>"
            f"<Table_Binary><offset unit=\"byte\">{offset}</offset><records>{records}</records>"
            f"<Record_Binary><fields>{len(layout)}</fields><groups>0</groups>"
            f"<record_length unit=\"byte\">{location - 1}</record_length>{''.join(fields)}"
            f"</Record_Binary></Table_Binary></File_Area_Observational>"
            f"</Product_Observational>\n")


def _records(layout, values: dict) -> bytes:
    dtype = np.dtype([(n, f"S{length}" if t == "ASCII_String" else NUMPY[t])
                      for n, t, length, _ in layout])
    rows = np.zeros(len(FLAGS), dtype)
    for name, column in values.items():
        rows[name] = column
    return rows.tobytes()


def _ola_values():
    rng = np.random.default_rng(0)
    n = len(FLAGS)
    points = rng.normal(0, 200, (n, 3))
    sc = points * 4
    et = 6.03e8 + np.arange(n) * 1e-4
    utc = spice.et_to_utc(et, style="ISOD")   # yyyy-doyThh:mm:ss.ssssss, 24 characters
    return {"met": [b"1/0521165299.31170"] * n, "utc": [u.encode() for u in utc], "et": et,
            "flag_status": FLAGS, "range": np.linalg.norm(sc - points, axis=1) * 1e3,
            "x": points[:, 0], "y": points[:, 1], "z": points[:, 2],
            "scx": sc[:, 0], "scy": sc[:, 1], "scz": sc[:, 2]}, points, sc, et


def test_ola_l2_reads_the_published_layout_and_drops_flagged_returns(tmp_path):
    values, points, sc, et = _ola_values()
    (tmp_path / "20190213_ola_scil2id02100.dat").write_bytes(_records(OLA_LAYOUT, values))
    label = tmp_path / "20190213_ola_scil2id02100.xml"
    label.write_text(_label("20190213_ola_scil2id02100.dat", len(FLAGS), OLA_LAYOUT))
    data = read_ola_l2(label)
    kept = [0, 4, 5, 7]
    np.testing.assert_array_equal(data.record, kept)
    np.testing.assert_array_equal(data.points, points[kept])
    np.testing.assert_array_equal(data.spacecraft, sc[kept])
    np.testing.assert_allclose(data.range, np.linalg.norm(sc - points, axis=1)[kept],
                               rtol=1e-14)
    np.testing.assert_array_equal(data.et, et[kept])
    assert data.dropped == {"valid return with overflow": 1, "no return": 2,
                            "missing sample": 1}
    table = read_label(label)
    assert table.record_length == 186 and len(table.fields) == 23
    assert table.fields["x"].location == 115 and table.fields["range"].location == 75


def test_ola_l2_takes_every_layout_detail_from_the_label(tmp_path):
    """Another order, big-endian types, a scaled single-precision field, a table after a
    header, the time as UTC only, km: the reader follows the label, not fixed offsets."""
    values, points, sc, et = _ola_values()
    layout = [("scz", "IEEE754MSBDouble", 8, "km"), ("flag_status", "SignedMSB2", 2, ""),
              ("utc", "ASCII_String", 24, ""), ("z", "IEEE754MSBDouble", 8, "km"),
              ("range", "IEEE754MSBSingle", 4, "m"), ("x", "IEEE754MSBDouble", 8, "km"),
              ("scx", "IEEE754MSBDouble", 8, "km"), ("y", "IEEE754MSBDouble", 8, "km"),
              ("scy", "IEEE754MSBDouble", 8, "km")]
    for name in ("x", "y", "z", "scx", "scy", "scz"):
        values[name] = values[name] / 1e3
    stored = np.linalg.norm(sc - points, axis=1)
    values["range"] = (stored - 500.0) / 0.5   # stored * 0.5 + 500 = range [m]
    header = b"H" * 37
    (tmp_path / "t.dat").write_bytes(header + _records(layout, {k: values[k] for k, *_ in
                                                               layout}))
    label = tmp_path / "t.xml"
    label.write_text(_label("t.dat", len(FLAGS), layout, offset=len(header),
                            scaling={"range": (0.5, 500.0)}))
    data = read_ola_l2(label)
    kept = [0, 4, 5, 7]
    np.testing.assert_allclose(data.points, points[kept], rtol=1e-12)
    np.testing.assert_allclose(data.spacecraft, sc[kept], rtol=1e-12)
    np.testing.assert_allclose(data.range, stored[kept], rtol=1e-6)   # float32 storage
    np.testing.assert_allclose(data.et, et[kept], atol=1e-6)          # from the UTC strings


@pytest.mark.parametrize(("change", "message"), [
    (lambda t: t.replace("<records>8</records>", "<records>9</records>"),
     r"t\.dat: 1,488 bytes, but its label t\.xml declares 9 records of 186 bytes"),
    (lambda t: t.replace("<file_name>t.dat", "<file_name>../t.dat"),
     r"<file_name> '\.\./t\.dat' must name a file beside the label"),
    (lambda t: t.replace("<name>range</name>", "<name>rng</name>"),
     r"t\.xml: the table has no field range"),
    (lambda t: t.replace("<data_type>SignedLSB2</data_type>", "<data_type>Int9</data_type>", 1),
     r"field 'power_cycle': unknown data_type 'Int9'"),
    (lambda t: t.replace('<field_location unit="byte">179</field_location>',
                         '<field_location unit="byte">180</field_location>'),
     r"field 'scz': bytes 180\.\.187 lie outside the 186-byte record"),
    (lambda t: t.replace("<unit>mm</unit>", "<unit>furlong</unit>"),
     r"field 'range' has unit 'furlong', not a length unit"),
    (lambda t: t.replace("<fields>23</fields>", "<fields>22</fields>"),
     r"<fields> says 22, the record has 23"),
    (lambda t: t.replace("<?xml version=\"1.0\" encoding=\"UTF-8\"?>",
                         '<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "b">]>'),
     r"declares no DOCTYPE or entities"),
    (lambda t: t[:200], r"t\.xml: not an XML label"),
    (lambda t: t.replace("<name>range</name><field_number>10</field_number>"
                         '<field_location unit="byte">75</field_location>'
                         "<data_type>IEEE754LSBDouble</data_type>",
                         "<name>range</name><field_number>10</field_number>"
                         '<field_location unit="byte">75</field_location>'
                         "<data_type>ASCII_String</data_type>"),
     r"field 'range' is ASCII_String, expected a number"),
])
def test_ola_l2_refuses_hostile_labels_in_one_line(tmp_path, change, message):
    values, *_ = _ola_values()
    (tmp_path / "t.dat").write_bytes(_records(OLA_LAYOUT, values))
    label = tmp_path / "t.xml"
    label.write_text(change(_label("t.dat", len(FLAGS), OLA_LAYOUT)))
    with pytest.raises(InputError, match=message) as caught:
        read_ola_l2(label)
    assert "\n" not in str(caught.value)


def test_hayabusa2_l2_reads_the_published_columns_in_metres(tmp_path):
    rng = np.random.default_rng(1)
    points, sc = rng.normal(0, 400, (5, 3)), rng.normal(0, 4000, (5, 3))
    et = 5.85e8 + np.arange(5)
    utc = spice.et_to_utc(et, style="ISOC")
    lines = []
    for k in range(5):
        r = np.linalg.norm(points[k])
        lon, lat = np.degrees(np.arctan2(points[k, 1], points[k, 0])), np.degrees(
            np.arcsin(points[k, 2] / r))
        cells = [np.linalg.norm(sc[k] - points[k]), lon, lat, r, *points[k], *sc[k]]
        if k == 2:
            cells[5] = float("nan")   # no footprint: dropped
        lines.append(utc[k] + "," + ",".join(f"{c:.6f}" for c in cells))
    path = tmp_path / "hyb2_ldr_l2_topo_ts.csv"
    path.write_text("\n".join(lines) + "\n")
    data = read_hayabusa2_l2(path)
    kept = [0, 1, 3, 4]
    np.testing.assert_array_equal(data.record, kept)
    np.testing.assert_allclose(data.points, points[kept], atol=1e-6)
    np.testing.assert_allclose(data.spacecraft, sc[kept], atol=1e-6)
    np.testing.assert_allclose(data.et, et[kept], atol=1e-6)
    assert data.dropped == {"missing values": 1}
    # a header of names with units, in another order, in km
    header = ("SC_POS_X [km],SC_POS_Y [km],SC_POS_Z [km],SHOT_TIME,RANGE(km),TOPO_LONGITUDE,"
              "TOPO_LATITUDE,TOPO_HEIGHT[km],TOPO_X[km],TOPO_Y[km],TOPO_Z[km]")
    rows = [f"{sc[k, 0] / 1e3:.9f},{sc[k, 1] / 1e3:.9f},{sc[k, 2] / 1e3:.9f},{utc[k]},"
            f"{np.linalg.norm(sc[k] - points[k]) / 1e3:.9f},0,0,0,"
            f"{points[k, 0] / 1e3:.9f},{points[k, 1] / 1e3:.9f},{points[k, 2] / 1e3:.9f}"
            for k in range(5)]
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    data = read_hayabusa2_l2(path)
    np.testing.assert_allclose(data.points, points, atol=1e-6)
    np.testing.assert_allclose(data.range, np.linalg.norm(sc - points, axis=1), atol=1e-6)


@pytest.mark.parametrize(("text", "message"), [
    ("2019-01-01T00:00:00,1,2,3\n", r"line 1 has 4 values, expected 11"),
    ("SHOT_TIME,RANGE [ft],TOPO_LONGITUDE,TOPO_LATITUDE,TOPO_HEIGHT,TOPO_X,TOPO_Y,TOPO_Z,"
     "SC_POS_X,SC_POS_Y,SC_POS_Z\n", r"column RANGE has unit 'ft', not a length unit"),
    ("SHOT_TIME,RANGE\n", r"header has no column TOPO_LONGITUDE"),
    ("someday," + ",".join(["1"] * 10) + "\n", r"SHOT_TIME: .*someday|SHOT_TIME"),
    ("", r"no lines"),
    ("2019-01-01T00:00:00,-5,0,0,0,1,2,3,100,0,0\n",
     r"bad\.csv: row 1: range -5 m is not a positive distance \(1 such row\(s\)\)"),
    ("2019-01-01T00:00:00,5,0,0,0,1,2,3,100,0,1e308\n",
     r"bad\.csv: spacecraft positions: coordinates reach 1e\+308 m"),
])
def test_hayabusa2_l2_refuses_bad_files_in_one_line(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as caught:
        read_hayabusa2_l2(path)
    assert "\n" not in str(caught.value)


def test_ola_l2_reads_no_table_a_symbolic_link_leads_out_of_the_label_s_directory(tmp_path):
    values, *_ = _ola_values()
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "t.dat").write_bytes(_records(OLA_LAYOUT, values))
    product = tmp_path / "product"
    product.mkdir()
    (product / "t.dat").symlink_to(outside / "t.dat")
    label = product / "t.xml"
    label.write_text(_label("t.dat", len(FLAGS), OLA_LAYOUT))
    with pytest.raises(InputError, match=r"<file_name> 't\.dat' leads out of the label's "
                                         r"directory"):
        read_ola_l2(label)
    (product / "t.dat").unlink()   # the same table beside the label is read
    (product / "t.dat").write_bytes(_records(OLA_LAYOUT, values))
    assert len(read_ola_l2(label).points) > 0
