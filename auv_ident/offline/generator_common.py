"""What the independent data generators (offline/independent_data.py and
offline/independent_rov.py) share that has nothing to do with a vehicle model: the start date
in ns, the output folder's preparation, the QoS profile their bags offer, a rotation matrix's
quaternion, and numpy values made JSON-ready for truth.json. Kept apart from both so that the
thruster generator need not import the fin generator (which imports auv_ident.core.model)."""
import datetime
import math
from pathlib import Path
import shutil

import numpy as np

NS = 1_000_000_000


def epoch_ns(text):
    """ns since 1970 of an ISO 8601 date ('...Z' or an offset; naive means UTC)."""
    d = datetime.datetime.fromisoformat(text.replace('Z', '+00:00'))
    if d.tzinfo is None:
        d = d.replace(tzinfo=datetime.timezone.utc)
    delta = d - datetime.datetime(1970, 1, 1, tzinfo=datetime.timezone.utc)
    return (delta.days * 86400 + delta.seconds) * NS + delta.microseconds * 1000


def qos():
    """The offered QoS of every topic: reliable, volatile, keep last 10 (a recorder's default)."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )
    inf = QosTime(9223372036, 854775807)
    return Qos(QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE, QosDurability.VOLATILE, inf,
               inf, QosLiveliness.AUTOMATIC, inf, False)


def jsonable(obj):
    """dicts, lists, tuples, arrays and numpy scalars as plain JSON values."""
    if isinstance(obj, dict):
        return {k: jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def quat_of(R):
    """Quaternion (x, y, z, w) of a rotation matrix (Shepperd's method)."""
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        return ((R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s,
                0.25 * s)
    i = int(np.argmax(np.diag(R)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
    q = np.empty(4)
    q[i] = 0.25 * s
    q[j] = (R[j, i] + R[i, j]) / s
    q[k] = (R[k, i] + R[i, k]) / s
    q[3] = (R[k, j] - R[j, k]) / s
    return tuple(q)


def prepare_out_dir(out_dir, overwrite, names):
    """The output folder, created; FileExistsError if it holds anything and not overwrite, else
    its earlier outputs ``names`` (files or folders) removed."""
    out_dir = Path(out_dir)
    if out_dir.exists() and any(out_dir.iterdir()):
        if not overwrite:
            raise FileExistsError(f'{out_dir} exists and is not empty (overwrite=True replaces)')
        for name in names:
            p = out_dir / name
            if p.is_dir():
                shutil.rmtree(p)
            elif p.exists():
                p.unlink()
    out_dir.mkdir(parents=True, exist_ok=True)
    return out_dir
