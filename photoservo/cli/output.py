"""What the verbs print: progress bars, strict JSON on stdout.

Progress bars are tqdm's: drawn on a terminal only (`disable=None`: none of tqdm's `\\r`
updates reach a log file or a pipe) and never under -q.
"""

from __future__ import annotations

import json
import logging
import math
import sys
from typing import Any

import numpy as np
from tqdm import tqdm


def progress(total: float, desc: str, unit: str = "it", **kwargs: Any) -> tqdm:
    """A tqdm bar on stderr, shown only when stderr is a terminal and the log level shows info."""
    quiet = not logging.getLogger().isEnabledFor(logging.INFO)
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True, leave=True,
                disable=True if quiet else None, **kwargs)


def jsonable(obj: Any) -> Any:
    """`obj` with NaN and +-inf as None, numpy scalars and arrays as Python numbers and lists,
    tuples as lists: what strict JSON (RFC 8259) can carry."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def dumps_strict(obj: Any, **kwargs: Any) -> str:
    """JSON text that strict parsers accept: NaN/Infinity written as null (never `NaN`)."""
    return json.dumps(jsonable(obj), allow_nan=False, **kwargs)


def print_json(obj: Any) -> None:
    """One strict JSON object on stdout."""
    print(dumps_strict(obj), flush=True)
