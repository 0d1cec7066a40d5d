"""Pictures: process maps and regressed surfaces, and 3-D views of a run.
"""
