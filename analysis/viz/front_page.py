"""What a finished map says, as reStructuredText for the report's front page.

``report/workflow.rst``, the front page of Snakemake's report, includes the file
:func:`write_front_page` writes (``results/<level>/front_page.rst``): the operating
window's recommended setting, the chosen model and why, the paper's network's test R
with its spread over seeded splits, the layer-structure metrics' scores (void fraction and
coverage, mapped beside eq. 7's porosity), and the size of the dataset.
"""
from __future__ import annotations

from analysis.columns import METRICS, SHORT_NAMES, STRUCTURE_METRICS, input_units
from analysis.io import write_text
from analysis.surrogate.candidates import CANDIDATES
from analysis.surrogate.predict import provides_intervals
from analysis.surrogate.recommend import check_limits, limits_text, recommend
from analysis.surrogate.selection import choice_rule_text, decide


def window_setting(model, meta, window):
    """The operating window's recommended setting (:func:`analysis.surrogate.recommend.recommend`).

    At the model's confidence when its intervals are finite, else on the mean (the window
    map's rule). Returns (the found dict or None, the rule as text).
    """
    finite = provides_intervals(model) and model.is_finite()
    judged = model if finite or not provides_intervals(model) else model.model
    found = recommend(judged, meta, **check_limits(window))
    if finite:
        return found, f"the upper end of the {100 * model.confidence:g} % single-run interval within each limit"
    return found, "the predicted mean within each limit (too few runs for a finite interval)"


def _structure_values(found):
    """The found setting's layer-structure metrics as text (', void fraction 35 %, coverage 98 %'), if any."""
    names = {"void_fraction_pct": "void fraction", "coverage_pct": "coverage"}
    return "".join(f", {names[m]} {found[m]:.3g} %" for m in STRUCTURE_METRICS if m in found)


def _num(x):
    return "n/a" if x is None else f"{x:.3f}"


def structure_line(record):
    """The layer-structure metrics' paragraph: their test R and k-fold R^2 (``scores.json``'s ``structure``)."""
    if not record:
        return ""
    if "skipped" in record:
        return f"**Layer structure** (void fraction, coverage): not fitted, {record['skipped']}."
    names = {"void_fraction_pct": "void fraction eps = 100 (1 - packing fraction)", "coverage_pct": "coverage C"}
    scores = "; ".join(f"{names[m]}: test R {_num(record['test'][m]['R'])}, k-fold R^2 "
                       f"{_num(record['cv']['kfold'][m]['R2'])}" for m in STRUCTURE_METRICS)
    return ("**Layer structure beside eq. 7** (``maps/void_fraction_pct_*.png``, ``maps/coverage_pct_*.png``): "
            "eq. 7's Phi takes 4 R_q as the layer's thickness, so it reads deep deposits as dense and thin, "
            f"patchy layers as porous; the same model ({record['model']}) maps the {scores} "
            "(``surrogate/scores.json``, ``structure``).")


def front_page_rst(scores, choice, window=None, found=None, rule=""):
    """The front page's facts as reStructuredText.

    Parameters
    ----------
    scores : dict
        scores.json (the paper's network's ``test`` and ``test_spread``, the chosen ``model``, the
        layer-structure metrics' ``structure``).
    choice : pandas.DataFrame
        model_choice.csv.
    window : dict, optional
        ``maps.operating_window`` (its limits).
    found : dict, optional
        :func:`window_setting`'s setting (None: no setting meets the limits).
    rule : str
        How a setting was judged (:func:`window_setting`).
    """
    symbols = " / ".join(s for s, _ in METRICS.values())
    lines = []
    if window is not None:
        lines += ["**The operating window** (``maps/operating_window.png``): " + limits_text(window) + ", judged by "
                  + rule + ". "]
        if found is None or not found.get("meets_confidence", True):
            lines[-1] += "**No setting in the swept range meets them**: relax the limits or simulate elsewhere."
        else:
            units = input_units(found["inputs"])
            setting = ", ".join(f"{SHORT_NAMES.get(c, c)} = {found[c]:.4g} {units[c]}".rstrip()
                                for c in found["inputs"])
            lines[-1] += (f"The highest predicted throughput there: **{setting}**, with Q_s "
                          f"{found['throughput_mm2_s']:.3g} mm^2/s, M_s {found['mass_g']:.3g} g, R_q "
                          f"{found['roughness_um']:.3g} um, Phi {found['porosity_pct']:.3g} %"
                          f"{_structure_values(found)}; "
                          f"{found['n_feasible']} of {found['n_grid']} settings of the search grid meet the limits.")
        lines.append("")
    name = scores["model"]["name"]
    order = list(dict.fromkeys(choice["model"]))
    d = decide(choice, order)
    chosen_kfold = choice[(choice["model"] == name) & (choice["scheme"] == "kfold")]
    lines += [f"**The model** behind every map: **{name}** ({CANDIDATES.get(name, name)}), chosen by grouped "
              f"repeated k-fold cross-validation over {scores['n_runs']} runs: {choice_rule_text(d)}. Its k-fold "
              f"R^2 ({symbols}): " + " / ".join(f"{v:.3f}" for v in chosen_kfold.set_index("metric").loc[
                  list(METRICS), "R2"]) + " (``surrogate/model_choice.md``).", ""]
    test = scores["test"]
    split = scores.get("split", {"n_train": 35, "n_test": 10})
    lines.append(f"**The paper's network** (Table 2) on the seeded {split['n_train']}/{split['n_test']}-run split "
                 f"by point (the paper's: 35/10), test R ({symbols}): "
                 + " / ".join("n/a" if test[m]["R"] is None else f"{test[m]['R']:.3f}" for m in METRICS)
                 + " (the paper: >= 0.96).")
    spread = scores.get("test_spread")
    if spread:
        lines[-1] += (f" One split is a noisy figure: over {spread['n_splits']} seeded splits its test R is "
                      + "; ".join(f"{METRICS[m][0]} {spread[m]['R_mean']:.3f} +- {spread[m]['R_sd']:.3f} "
                                  f"({spread[m]['R_min']:.3f} to {spread[m]['R_max']:.3f})" for m in METRICS)
                      + " (mean +- sd, min to max; ``surrogate/scores.json``, ``test_spread``)."
                      + (" The R of two test runs is +-1 whatever the fit: too few to score." if
                         spread.get("n_test", 10) < 3 else ""))
    lines.append("")
    if scores.get("structure"):
        lines += [structure_line(scores["structure"]), ""]
    return "\n".join(lines)


def write_front_page(path, scores, choice, model=None, meta=None, window=None):
    """Write :func:`front_page_rst` to ``path`` (atomically), the window's setting found from ``model``."""
    found, rule = (None, "")
    if window is not None and model is not None:
        found, rule = window_setting(model, meta, window)
    return write_text(front_page_rst(scores, choice, window, found, rule), path)
