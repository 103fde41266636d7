"""Studies of a site: compliance, estimator selection, mixed-traffic scoring and the report.

The top floor of the crossing: it may use every other wing.
"""
