"""crowdnav's scenario library: one YAML file per scenario (data only, see crowdnav.scenario)."""
