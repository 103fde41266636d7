"""The site model, the ground floor every other wing of the crossing reads.

Roads and corridors, radars and their curves, road-user classes and cases, the strict site
file format and its authoring, the drawings, and the one compiled ground geometry
(:mod:`.geometry`) that simulation, estimators and the scene tracker all stand on.
"""
