//! PGM's settings (config `[method] name = "pgm"`, `docs/pgm.md`).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::lod::sweep::Sweep;

#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct PgmSettings {
    /// Grid vertices across the screen (left to right).
    pub grid_cols: u32,
    /// Grid vertices from the bottom of the auxiliary view up to the horizon.
    pub grid_rows: u32,
    /// Smallest field of view of the auxiliary camera in degrees (90..=170), both
    /// horizontally and vertically; its pitch is clamped to at most `-fov_deg / 2`.
    pub fov_deg: f64,
    /// Lowest height of the auxiliary camera above the reference plane (the terrain under the
    /// camera), metres.
    pub min_height_m: f64,
    /// Rows warped towards the horizon (half uniform in the image plane, half uniform in the
    /// logarithm of the ground distance; `AuxCamera::row_fractions`); `false`: every row
    /// uniform in the image plane (the plain grid, which drops distant peaks seen from low).
    pub warp_rows: bool,
    /// On the earth, each grid ray meets the curved reference surface and its point maps to
    /// the sample under it through the geolocation lattice (docs/pgm.md, "On the earth");
    /// `false`: an ablation, the flat world's projection (ground offsets in the world frame
    /// read as grid offsets from the camera's world cell), the negative control of the
    /// coverage test. No effect on the flat world.
    pub earth_projection: bool,
}

impl Default for PgmSettings {
    fn default() -> Self {
        PgmSettings {
            grid_cols: 240,
            grid_rows: 1050,
            fov_deg: 90.0,
            min_height_m: 2.0,
            warp_rows: true,
            earth_projection: true,
        }
    }
}

impl PgmSettings {
    /// What `vkterrain eval --sweep KEY=...` varies for PGM.
    pub const SWEEP: &[Sweep<Self>] = &[
        Sweep {
            key: "grid_scale",
            help: "both sides of the configured grid times the value (0.5: 240x1050 -> 120x525)",
            apply: |s, v| {
                let scaled = |n: u32| ((n as f64 * v).round() as u32).max(2);
                s.grid_cols = scaled(s.grid_cols);
                s.grid_rows = scaled(s.grid_rows);
            },
        },
        Sweep {
            key: "grid_cols",
            help: "grid vertices across the screen",
            apply: |s, v| s.grid_cols = v as u32,
        },
        Sweep {
            key: "grid_rows",
            help: "grid vertices towards the horizon",
            apply: |s, v| s.grid_rows = v as u32,
        },
        Sweep {
            key: "fov_deg",
            help: "least field of view of the auxiliary camera",
            apply: |s, v| s.fov_deg = v,
        },
        Sweep {
            key: "warp_rows",
            help: "1: rows warped towards the horizon (default), 0: uniform in the image plane",
            apply: |s, v| s.warp_rows = v != 0.0,
        },
        Sweep {
            key: "earth_projection",
            help: "1: rays meet the curved surface on the earth (default), 0: the flat world's projection (ablation)",
            apply: |s, v| s.earth_projection = v != 0.0,
        },
    ];

    /// `[columns, rows]` of the grid.
    pub fn grid(&self) -> [u32; 2] {
        [self.grid_cols, self.grid_rows]
    }

    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("pgm settings", m));
        let [cols, rows] = self.grid();
        if !(2..=4096).contains(&cols) || !(2..=16384).contains(&rows) {
            return bad(format!(
                "grid {cols}x{rows} needs 2..=4096 columns and 2..=16384 rows"
            ));
        }
        if cols as u64 * rows as u64 > 1 << 24 {
            return bad(format!(
                "grid {cols}x{rows} has more than 16777216 vertices"
            ));
        }
        if !(self.fov_deg.is_finite() && (90.0..=170.0).contains(&self.fov_deg)) {
            return bad(format!(
                "fov_deg {} must be within 90..=170 degrees",
                self.fov_deg
            ));
        }
        if !(self.min_height_m.is_finite()
            && self.min_height_m > 0.0
            && self.min_height_m <= 100_000.0)
        {
            return bad(format!(
                "min_height_m {} must be within (0, 100000] metres",
                self.min_height_m
            ));
        }
        Ok(())
    }
}
