"""Single-object road estimators: the road EKFs, their IMM, generated kernels and the PCRLB.

Stands on :mod:`adaptrack.crossing.site` and the library's filters; never imports the
simulation.
"""
