"""Snakemake entry: deposit profiles (layer mass along the travel) of a few runs, region shaded."""

from analysis.config.fidelity import scene
from analysis.io import atomic_path
from analysis.metrics.deposit import profile_figure, run_profiles
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    s = scene(config, snakemake.params.level)
    runs = [{"U_mm_s": U, "omega_rad_s": w, "replicate": r} for U, w, r in snakemake.params.runs]
    profiles = run_profiles(snakemake.input, runs, s.density, s.strip_width, (s.box[0], s.travel_end))
    with atomic_path(snakemake.output.csv) as tmp:
        profiles.to_csv(tmp, index=False)
    region = tuple(v * 1e3 for v in s.sampling_region[:2])
    with atomic_path(snakemake.output.png) as tmp:
        profile_figure(profiles, region, f"Deposit profiles, level {s.level}").savefig(tmp, dpi=130)
