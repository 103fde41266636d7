"""The many-objects scene tracker: raw detections in, tracks and hazard events out.

One module per stage of a scan (body model, predict, gate, update, spawn, prune, modes), the
compiled scan loop that runs them, and :mod:`.tracker`, the Python face. Stands on the site,
the estimators' measurement kernels and the generic :mod:`adaptrack.tracking` layer; never
imports the simulation.
"""
