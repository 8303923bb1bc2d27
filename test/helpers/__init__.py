"""Test utilities shared across layers (importable as `helpers`)."""
