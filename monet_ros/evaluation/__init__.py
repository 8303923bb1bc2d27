"""PCK, reprojection error, report tables and plots."""
from monet_ros.evaluation.pck import PCK_THRESHOLDS, PCKResult, normalised_distances, pck
from monet_ros.evaluation.report import (
                                         MODE_ORDER,
                                         EvalSummary,
                                         csv_table,
                                         load_summaries,
                                         markdown_table,
                                         write_report,
)

__all__ = ['normalised_distances', 'pck', 'PCK_THRESHOLDS', 'PCKResult', 'EvalSummary',
           'csv_table', 'load_summaries', 'markdown_table', 'MODE_ORDER', 'write_report']
