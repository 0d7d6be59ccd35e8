"""crowdnav tests of the core layer (tests/README.md)."""
