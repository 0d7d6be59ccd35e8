"""crowdnav's tests: a package, so shared helpers import by name (``from tests.agents.agents_tiny import tiny_config``)."""
