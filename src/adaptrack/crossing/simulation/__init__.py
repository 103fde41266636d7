"""Simulated worlds of a site: traffic scenes, radar detections and object lists.

Stands on :mod:`adaptrack.crossing.site` only: it never imports the estimators or the scene
tracker, so that an error in one of them cannot hide in a helper both share.
"""
