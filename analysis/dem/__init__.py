"""The DEM engine's side: scene geometry, LIGGGHTS inputs and runs, and the health of a run.
"""
