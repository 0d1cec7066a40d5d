"""The dataset's column vocabulary: the four layer metrics, the layer-structure metrics mapped
beside them, the inputs and their units, how text names them. The ground floor: it imports nothing
of the package, every layer may use it."""
from __future__ import annotations

# The four layer metrics of the paper (eqs. 1-7): dataset column -> (symbol, unit)
METRICS = {
    "mass_g": ("M_s", "g"),
    "throughput_mm2_s": ("Q_s", "mm^2/s"),
    "roughness_um": ("R_q", "um"),
    "porosity_pct": ("Phi", "%"),
}

#: Layer-structure metrics mapped beside the paper's four (not part of its method, nor of the model
#: choice's score): dataset column -> (symbol, unit). Eq. 7's Phi takes 4 R_q as the layer's
#: thickness; these do not. ``void_fraction_pct``: 100 (1 - packing fraction), the void share of the
#: volume under the measured layer top (``packing_fraction``: the particles' solid volume over
#: L_x L_y thk_avg); ``coverage_pct``: 100 x the share of profilometer probes that hit powder
#: (``coverage``). Both derived from dataset.csv's columns by
#: :func:`analysis.metrics.dataset.with_structure_metrics`.
STRUCTURE_METRICS = {
    "void_fraction_pct": ("eps", "%"),
    "coverage_pct": ("C", "%"),
}

#: Every mapped metric: the paper's four, then the layer-structure ones.
ALL_METRICS = {**METRICS, **STRUCTURE_METRICS}

#: Input columns and their units: the spreader's speeds, in every dataset. A sweep's extra
#: axes (config keys, ``sweep.<dotted key>``) are inputs too: columns named by their dotted
#: path, after these (:func:`input_columns`).
INPUTS = {"U_mm_s": "mm/s", "omega_rad_s": "rad/s"}

#: How text names the speeds; a swept config key is named by its dotted path.
SHORT_NAMES = {"U_mm_s": "U", "omega_rad_s": "omega"}

#: Units of a config key, from its name's ending (the config's convention); none: dimensionless.
_UNIT_SUFFIXES = {"_mm_s": "mm/s", "_rad_s": "rad/s", "_kg_m3": "kg/m^3", "_J_m3": "J/m^3", "_Pa": "Pa",
                  "_mg_per_mm": "mg/mm", "_um": "um", "_mm": "mm", "_s": "s"}


def input_columns(df) -> list[str]:
    """The inputs of a dataset: ``U_mm_s``, ``omega_rad_s``, then its swept config keys
    (the columns whose name is a dotted path, e.g. ``roller.gap_um``), in column order."""
    return [*INPUTS, *(c for c in df.columns if "." in str(c))]


def input_units(columns) -> dict:
    """``{column: unit}`` of input columns, the unit read off the key's name (``gap_um``: um)."""
    return {c: INPUTS.get(c) or next((u for end, u in _UNIT_SUFFIXES.items() if c.endswith(end)), "")
            for c in columns}


def point_label(point: dict) -> str:
    """A point's short name: ``U70_w-10``, with the extra axes' values: ``U70_w-10_roller.gap_um=200``."""
    extra = "".join(f"_{k}={v:g}" for k, v in point.items() if k not in INPUTS)
    return f"U{point['U_mm_s']:g}_w{point['omega_rad_s']:g}{extra}"
