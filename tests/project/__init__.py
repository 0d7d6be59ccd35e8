"""crowdnav tests of the project layer (tests/README.md)."""
