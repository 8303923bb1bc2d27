"""Synthetic calibrated rig and articulated subject renderer."""
