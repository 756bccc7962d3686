"""Real laser altimetry in, and strike logs out as altimetry products (formats/altimetry.py).

``recon ingest PRODUCT -o CLOUD`` reads an OSIRIS-REx OLA Level-2 table through its PDS4 label
(``.xml``) or a Hayabusa2 LIDAR Level-2 CSV (``.csv``): the products already place each return
in the target's body-fixed frame, so ingesting keeps those points (no registration) with, per
point, ``time`` [s since the product's first kept return], ``et`` [s TDB past J2000],
``shot`` (the return's row in the product), ``range`` [m] and, where the product gives the
spacecraft position, the view point ``view_x/y/z`` [m, body frame]. Dropped rows (flagged
returns, missing values) are counted by reason.

``recon altimetry LOG -o PRODUCT`` writes a strike log's strikes in either layout, registered
with the recorded poses only (as ``recon ingest`` places them), so a simulated campaign can be
read by the tools that read the missions' products, and read back by recon. An OLA table also
gets one ``no return`` row (``flag_status`` 2, zeros) for each pulse that struck nothing, as
the instrument records them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from formats import StrikeLog
from formats.altimetry import (
    Altimetry,
    read_hayabusa2_l2,
    read_ola_l2,
    write_hayabusa2_l2,
    write_ola_l2,
)
from formats.cloud_io import open_cloud_writer
from formats.errors import InputError
from formats.geometry import Cloud
from recon.registration.ingest import ingest

# Product suffix -> reader.
READERS = {".xml": read_ola_l2, ".csv": read_hayabusa2_l2}
PRODUCTS = ("ola", "hayabusa2")
ATTRIBUTE_DTYPES = {"time": np.float64, "et": np.float64, "shot": np.uint32,
                    "range": np.float64, "view_x": np.float64, "view_y": np.float64,
                    "view_z": np.float64}


def is_altimetry(path) -> bool:
    """True when ``path`` names an altimetry product by its suffix (``.xml``, ``.csv``)."""
    return Path(path).suffix.lower() in READERS


def read_altimetry(path) -> Altimetry:
    """An OLA Level-2 label (``.xml``) or a Hayabusa2 LIDAR Level-2 CSV (``.csv``)."""
    suffix = Path(path).suffix.lower()
    if suffix not in READERS:
        raise InputError(f"{path}: an altimetry product is an OLA Level-2 label (.xml) or a "
                             "Hayabusa2 LIDAR Level-2 CSV (.csv)")
    return READERS[suffix](path)


def altimetry_cloud(data: Altimetry) -> Cloud:
    """The returns of a product as a body-frame cloud with the attributes of the module
    docstring (``view_x/y/z`` only when the product gives the spacecraft position)."""
    if len(data) == 0:
        raise InputError(f"{data.source}: no returns to ingest ("
                             + (", ".join(f"{n} {why}" for why, n in data.dropped.items())
                                or "empty") + ")")
    attributes = {"time": data.et - data.et[0], "et": data.et,
                  "shot": data.record.astype(np.uint32), "range": data.range}
    if data.spacecraft is not None:
        attributes |= {"view_x": data.spacecraft[:, 0], "view_y": data.spacecraft[:, 1],
                       "view_z": data.spacecraft[:, 2]}
    return Cloud(data.points, attributes, frame="body")


def ingest_altimetry(path, output) -> dict:
    """Read an altimetry product and write its body-frame cloud (.ply, .las, .laz, .h5).

    Returns
    -------
    dict
        ``n_points``, ``dropped`` (reason -> rows), ``product``, ``output``.
    """
    data = read_altimetry(path)
    cloud = altimetry_cloud(data)
    dtypes = {k: v for k, v in ATTRIBUTE_DTYPES.items() if k in cloud.attributes}
    with open_cloud_writer(output, len(cloud.points), dtypes, frame="body",
                           source=Path(path).name) as writer:
        writer.write(cloud.points, {k: np.asarray(cloud.attributes[k], dtype=v)
                                    for k, v in dtypes.items()})
    return {"n_points": len(cloud.points), "dropped": data.dropped, "product": data.product,
            "output": str(Path(output))}


def _clock_strings(et: np.ndarray, epoch: float) -> tuple[np.ndarray, np.ndarray]:
    """``met`` strings (``1/SSSSSSSSSS.TTTTT`` of recon's SCLK, formats/spice.py) and the
    fractional ``met_offset`` ticks of each ET."""
    from formats.spice import CLOCK_MARGIN_S, CLOCK_TICKS_PER_S

    ticks = (et - (epoch - CLOCK_MARGIN_S)) * CLOCK_TICKS_PER_S
    whole = np.floor(ticks)
    seconds, rest = np.divmod(whole.astype(np.int64), CLOCK_TICKS_PER_S)
    met = np.char.add(np.char.add("1/", np.char.zfill(seconds.astype(str), 10)),
                      np.char.add(".", np.char.zfill(rest.astype(str), 5)))
    return met.astype("S18"), ticks - whole


def export_altimetry(log, output, *, product: str | None = None,
                     epoch_et: float | None = None) -> dict:
    """Write a strike log's strikes as an altimetry product (see the module docstring).

    The log is registered in memory (its cloud, and for OLA one 186-byte row per pulse).

    Parameters
    ----------
    log : str or Path
    output : str or Path
        ``.xml`` for OLA Level 2 (the ``.dat`` table is written beside it) or ``.csv`` for
        Hayabusa2 LIDAR Level 2.
    product : {"ola", "hayabusa2"}, optional
        Default: from the suffix.
    epoch_et : float, optional
        ET [s] of the log's time 0 (default: the log's ``epoch_et``, else 0).

    Returns
    -------
    dict
        ``n_returns``, ``n_no_return`` (OLA rows of pulses that struck nothing), ``product``,
        ``written``.
    """
    from formats.spice import et_to_utc
    from recon.registration.trajectory import log_epoch

    output = Path(output)
    suffix = output.suffix.lower()
    product = product or {".xml": "ola", ".csv": "hayabusa2"}.get(suffix)
    if product not in PRODUCTS or (product, suffix) not in (("ola", ".xml"),
                                                           ("hayabusa2", ".csv")):
        raise InputError(f"{output}: an OLA Level-2 product is written as its .xml label, "
                             "a Hayabusa2 LIDAR Level-2 product as .csv")
    with StrikeLog(log) as strike_log:
        epoch = log_epoch(strike_log, epoch_et)
        n_shots, n_beams = strike_log.n_shots, strike_log.sensor.n_beams
        shot_time = strike_log.shots().time
    cloud = ingest(log)
    a = cloud.attributes
    et = epoch + a["time"]
    if product == "hayabusa2":
        written = write_hayabusa2_l2(output, utc=et_to_utc(et, style="ISOC"),
                                     range_m=a["range"], points=cloud.points,
                                     spacecraft=cloud.view_points)
        return {"n_returns": len(et), "n_no_return": 0, "product": product,
                "written": [str(written)]}
    # One row per pulse in (shot, beam) order: the returns, and "no return" rows between.
    pulse = a["shot"].astype(np.int64) * n_beams + a["beam"]
    rows = np.zeros(n_shots * n_beams, dtype=bool)
    rows[pulse] = True
    all_et = epoch + np.repeat(shot_time, n_beams)
    met, offset = _clock_strings(all_et, epoch)
    columns = {"met": met, "met_offset": offset,
               "utc": np.array(et_to_utc(all_et, style="ISOD"), dtype="S24"),
               "et": all_et, "scan_ola_time": np.repeat(shot_time, n_beams),
               "flag_status": np.where(rows, 0, 2).astype(np.int16)}
    radius = np.linalg.norm(cloud.points, axis=1)
    returns = {"range": a["range"] * 1e3, "azimuth": a["azimuth"] * 1e3,
               "elevation": a["elevation"] * 1e3, "x": cloud.points[:, 0],
               "y": cloud.points[:, 1], "z": cloud.points[:, 2],
               "elongitude": np.degrees(np.arctan2(cloud.points[:, 1], cloud.points[:, 0]))
               % 360.0,
               "latitude": np.degrees(np.arcsin(cloud.points[:, 2] / radius)),
               "radius": radius / 1e3, "scx": a["view_x"], "scy": a["view_y"],
               "scz": a["view_z"]}
    for name, values in returns.items():
        column = np.zeros(len(rows))
        column[pulse] = values
        columns[name] = column
    label, data = write_ola_l2(output, columns,
                               title=f"OLA Level 2 layout, simulated by recon from "
                                     f"{Path(log).name}")
    return {"n_returns": int(rows.sum()), "n_no_return": int((~rows).sum()),
            "product": product, "written": [str(label), str(data)]}
