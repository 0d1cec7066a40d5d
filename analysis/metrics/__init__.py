"""From dumps to numbers: the virtual profilometer and the layer metrics (paper eqs. 1-7), the
dataset, the noise floor, trends and deposit profiles.
"""
