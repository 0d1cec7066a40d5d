"""Save and load a fitted surrogate (joblib, with a format tag and the
metadata of its fit); a file of another format or version is refused.
"""

from __future__ import annotations

import warnings

import joblib
import sklearn

from analysis.io import atomic_path
from analysis.surrogate.data import column_metadata

_FORMAT = "spreadmap-surrogate/1"


def save_surrogate(model, path, meta):
    """Save a fitted surrogate with its metadata (joblib, written atomically).

    Parameters
    ----------
    model : estimator
        The fitted surrogate.
    path : str or pathlib.Path
        Output file (``.joblib``).
    meta : dict
        What to keep with it; pass the ``scores`` of :func:`fit_surrogate`
        (it holds the split, the input range and the parameters).  The
        scikit-learn version is added (``sklearn_version``), and the input and
        metric names and units (``inputs``, in the model's column order, and
        ``metrics``) unless ``meta`` has them (default inputs: the speeds).
    """
    meta = {**column_metadata(), **meta, "sklearn_version": sklearn.__version__}
    with atomic_path(path) as tmp:
        joblib.dump({"format": _FORMAT, "model": model, "meta": meta}, tmp)


def load_surrogate(path):
    """Load a surrogate saved by :func:`save_surrogate`.

    Returns
    -------
    model : estimator
    meta : dict

    Warns
    -----
    UserWarning
        If it was saved with another scikit-learn version than the installed
        one (predictions may differ or fail); the message names both.
    """
    saved = joblib.load(path)
    if not isinstance(saved, dict) or saved.get("format") != _FORMAT:
        raise ValueError(f"{path} is not a spreadmap surrogate ({_FORMAT})")
    made_with = saved["meta"].get("sklearn_version")
    if made_with != sklearn.__version__:
        warnings.warn(f"{path} was saved with scikit-learn {made_with} but scikit-learn "
                      f"{sklearn.__version__} is installed; refit it if predictions look wrong",
                      UserWarning, stacklevel=2)
    return saved["model"], saved["meta"]
