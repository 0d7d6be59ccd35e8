"""crowdnav tests of the agents layer (tests/README.md)."""
