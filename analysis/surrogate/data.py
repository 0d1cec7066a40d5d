"""The Design of Simulations' dataset as a regression problem: input and
target columns, (U, omega) point labels, grouped splits and folds (replicates
of a point never straddle a split), point means and split files.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from sklearn.model_selection import GroupKFold, GroupShuffleSplit, LeaveOneGroupOut

from analysis.columns import INPUTS, METRICS, input_columns, input_units
from analysis.metrics.dataset import point_groups


def split_runs(df, n_test, seed):
    """Split the runs into training and test sets by (U, omega) point, reproducibly.

    All replicates of one point fall on the same side, so a test point is
    never seen in training through its twin.  With one run per point this is
    the plain seeded split of the runs.

    Parameters
    ----------
    df : pandas.DataFrame
        One row per DEM run.
    n_test : int
        Number of test (U, omega) points (the paper: 10 of 45).
    seed : int
        Seed of the shuffle.

    Returns
    -------
    train_idx, test_idx : numpy.ndarray of int
        Sorted row positions (``df.iloc``) of the training and test runs.
    """
    groups = point_groups(df)
    n = int(groups.max()) + 1 if len(groups) else 0
    if not 1 <= n_test < n:
        raise ValueError(f"n_test={n_test} must be between 1 and {n - 1} for {n} (U, omega) points")
    splitter = GroupShuffleSplit(n_splits=1, test_size=int(n_test), random_state=int(seed))
    train, test = next(splitter.split(groups, groups=groups))
    return np.sort(train), np.sort(test)


def point_folds(df, folds, seed):
    """Shuffled k-fold splits of the runs by (U, omega) point (replicates stay together).

    ``GroupKFold(folds, shuffle=True, random_state=seed)`` over the runs,
    grouped by :func:`point_groups`; with as many folds as points, one point
    is left out at a time (``LeaveOneGroupOut``).

    Returns
    -------
    list of (train_idx, test_idx)
        Row positions, usable as ``cv=`` of scikit-learn's model selection.
    """
    groups = point_groups(df)
    n = int(groups.max()) + 1
    if not 2 <= int(folds) <= n:
        raise ValueError(f"cv folds={folds} must be between 2 and the {n} (U, omega) points")
    splitter = (LeaveOneGroupOut() if int(folds) == n
                else GroupKFold(int(folds), shuffle=True, random_state=int(seed)))
    return list(splitter.split(groups, groups=groups))


def split_table(df, train_idx, test_idx):
    """The split as a table (for split.csv): row, U_mm_s, omega_rad_s, the extra axes, replicate/seed if
    present, set."""
    if len(train_idx) + len(test_idx) != len(df):
        raise ValueError("train and test rows do not cover the dataset")
    table = df[[c for c in (*input_columns(df), "replicate", "seed") if c in df.columns]].reset_index(drop=True)
    table.insert(0, "row", np.arange(len(df)))
    table["set"] = "train"
    table.loc[np.asarray(test_idx), "set"] = "test"
    return table


def read_split(path, df):
    """Read split.csv back as ``(train_idx, test_idx)``, checked against ``df``.

    Raises
    ------
    ValueError
        If the file's rows do not match ``df`` (different run count or speeds),
        i.e. the split was made on another dataset.
    """
    table = pd.read_csv(path)
    inputs = input_columns(df)
    if len(table) != len(df) or input_columns(table) != inputs or not np.allclose(
            table[inputs].to_numpy(float), df[inputs].to_numpy(float)):
        raise ValueError(f"{path} does not match the dataset's runs (rows, inputs or their values differ)")
    is_test = (table["set"] == "test").to_numpy()
    rows = table["row"].to_numpy()
    return np.sort(rows[~is_test]), np.sort(rows[is_test])


def inputs_of(df):
    """(n, k) float array of the inputs: U [mm/s], omega [rad/s], then the extra axes
    (:func:`analysis.columns.input_columns`, their config units)."""
    return df[input_columns(df)].to_numpy(float)


def targets_of(df):
    """(n, 4) float array of the metrics in :data:`METRICS` order."""
    return df[list(METRICS)].to_numpy(float)


def column_metadata(df=None):
    """Input (in model order: those of ``df``, default the speeds) and metric columns with their
    units, for scores and metadata."""
    return {"inputs": input_units(list(INPUTS) if df is None else input_columns(df)),
            "metrics": {m: {"symbol": s, "unit": u} for m, (s, u) in METRICS.items()}}


def check_dataset(df):
    """Raise KeyError naming the input or metric columns ``df`` lacks, ValueError naming the rows whose
    inputs or metrics are missing or not finite: what a model can be fitted on."""
    missing = [c for c in (*input_columns(df), *METRICS) if c not in df.columns]
    if missing:
        raise KeyError(f"dataset lacks columns: {', '.join(missing)}")
    bad = ~np.isfinite(np.c_[inputs_of(df), targets_of(df)]).all(axis=1)
    if bad.any():
        raise ValueError(f"dataset rows {np.flatnonzero(bad).tolist()} have missing or "
                         "non-finite speeds or metrics; fix or drop those runs first")
