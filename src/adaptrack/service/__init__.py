"""Live crossing service: detections from sockets or stdin, tracks and events out, a live page.

:mod:`.messages` parses input lines and encodes output records, :mod:`.reorder` merges the
radars' scans by time within a bounded window, :mod:`.engine` runs the scene tracker on them
with counters and state snapshots (no sockets: the same numbers as offline ``track``),
:mod:`.server` wires it to UDP / TCP / stdin, subscribers and the live page (:mod:`.web`),
and :mod:`.replay` feeds a recorded file to it.
"""
