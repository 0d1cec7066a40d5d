"""Regression of the layer metrics over (U, omega): the paper's network and other candidates,
their choice, adaptive design and the operator's recommendation.
"""
