"""crowdnav tests of the cli layer (tests/README.md)."""
