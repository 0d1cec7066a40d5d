"""From dumps to numbers: the virtual profilometer (paper eqs. 1-7), the dataset, the noise floor,
trends and deposit profiles.
"""
