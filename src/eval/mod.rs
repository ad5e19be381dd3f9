//! Measuring methods against the exact surface: geometric error from depth buffers, image
//! metrics and temporal stability, defined once on the CPU ([`metrics`]) and computed where the
//! frames are on the GPU ([`gpu`], proven equal by [`check`]); FLIP ([`flip`]); whole
//! evaluations over scenarios, methods and parameter sweeps ([`run`]), and their outputs:
//! tables, charts and images ([`report`], [`chart`], [`table`]). The definitions are written
//! down in `docs/metrics.md`.

pub mod chart;
pub mod check;
pub mod coarse;
pub mod flip;
pub mod gpu;
pub mod metrics;
pub mod oracle;
pub mod report;
pub mod run;
pub mod table;

/// One line per variant whose LOD budget overflowed in some measured frame (those frames are
/// coarser than the variant's settings ask: UDLOD's `max_tiles`); printed by `vkterrain eval`
/// and written into the report.
pub fn budget_warnings(summaries: &[run::RunSummary]) -> Vec<String> {
    summaries
        .iter()
        .filter(|s| s.budget_overflow_frames > 0)
        .map(|s| {
            format!(
                "{}: the LOD budget overflowed in {} of {} measured frames (UDLOD: raise `max_tiles` or coarsen `grid_size`); those frames are coarser than the settings ask",
                s.variant, s.budget_overflow_frames, s.frames
            )
        })
        .collect()
}
