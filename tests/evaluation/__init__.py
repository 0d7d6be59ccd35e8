"""crowdnav tests of the evaluation layer (tests/README.md)."""
