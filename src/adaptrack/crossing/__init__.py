"""Railway level-crossing application: site model, traffic, radar simulation, tracking."""
