"""The street domain: each street concept of the twin in one typed place (see docs/architecture.md)."""
