"""PCK, reprojection error, report tables and plots."""
