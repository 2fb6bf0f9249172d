"""Model discrepancy (issue 7): records, the load estimate, equation residuals, gap measures and
the sparse selection of the missing effect. Pure numpy/polars; the model's terms are passed in
as arrays by ``transforms.discrepancy.pipeline`` (transforms does not import the model)."""

from transforms.discrepancy.gaps import GAP_SCALES, GAP_SIGNALS, GapAccumulator, normalised_gap
from transforms.discrepancy.load import LoadEstimate, estimate_load, segment_levels
from transforms.discrepancy.records import REGIONS, Record, operating_regions, prepare_record, savgol, split_records
from transforms.discrepancy.residuals import demean_by_group, interval_edges, interval_residuals, pointwise_residuals
from transforms.discrepancy.selection import block_stats, cv_losses, forward_select, score_candidates
from transforms.discrepancy.settings import DiscrepancySettings

__all__ = [
    "GAP_SCALES", "GAP_SIGNALS", "GapAccumulator", "normalised_gap",
    "LoadEstimate", "estimate_load", "segment_levels",
    "REGIONS", "Record", "operating_regions", "prepare_record", "savgol", "split_records",
    "demean_by_group", "interval_edges", "interval_residuals", "pointwise_residuals",
    "block_stats", "cv_losses", "forward_select", "score_candidates",
    "DiscrepancySettings",
]
