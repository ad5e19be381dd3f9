//! The one table of a run's summaries: every place that prints summaries (`vkterrain eval`,
//! `benches/eval.rs`, `report.md`) renders these columns, as aligned text or as Markdown.

use super::run::RunSummary;

/// One column: its header and how a summary fills its cell.
pub struct Column<T> {
    pub header: &'static str,
    pub cell: fn(&T) -> String,
}

/// The summary columns, in order.
pub const SUMMARY_COLUMNS: &[Column<RunSummary>] = &[
    Column {
        header: "variant",
        cell: |s| s.variant.clone(),
    },
    Column {
        header: "GPU ms (median / p99)",
        cell: |s| format!("{:.2} / {:.2}", s.gpu_ms.median, s.gpu_ms.p99),
    },
    Column {
        header: "eval GPU ms",
        cell: |s| format!("{:.2}", s.gpu_eval_ms_median),
    },
    Column {
        header: "triangles",
        cell: |s| format!("{:.0}", s.triangles_median),
    },
    Column {
        header: "tiles",
        cell: |s| match s.tiles_median {
            Some(t) => format!("{t:.0}"),
            None => "-".into(),
        },
    },
    Column {
        header: "UDLOD/oracle",
        cell: |s| match s.oracle_ratio_median {
            Some(r) => format!("{r:.2}"),
            None => "-".into(),
        },
    },
    Column {
        header: "error px (mean / p99.9 / max)",
        cell: |s| {
            let p = &s.error.pixels;
            format!("{:.3} / {:.3} / {:.3}", p.mean, p.p999, p.max)
        },
    },
    Column {
        header: "coarse px p99.9 (share)",
        cell: |s| match s.coarse {
            Some(c) if c.share > 0.0 => format!("{:.3} ({:.1}%)", c.p999_px, 100.0 * c.share),
            Some(_) => "- (0%)".into(),
            None => "-".into(),
        },
    },
    Column {
        header: "error m (p99.9)",
        cell: |s| format!("{:.3}", s.error.metres.p999),
    },
    Column {
        header: "holes (cracks)",
        cell: |s| format!("{} ({})", s.holes_total, s.cracks_total),
    },
    Column {
        header: "silhouette px",
        cell: |s| s.silhouette_px_max.to_string(),
    },
    Column {
        header: "PSNR dB",
        cell: |s| format!("{:.1}", s.psnr_db_mean),
    },
    Column {
        header: "SSIM",
        cell: |s| format!("{:.4}", s.ssim_mean),
    },
    Column {
        header: "FLIP (mean / p99)",
        cell: |s| match (s.flip_mean, s.flip_p99_mean) {
            (Some(m), Some(p)) => format!("{m:.4} / {p:.4}"),
            _ => "-".into(),
        },
    },
    Column {
        header: "popping px (median / max)",
        cell: |s| format!("{:.4} / {:.4}", s.popping_px.median, s.popping_px.max),
    },
    Column {
        header: "swimming px (mean / p99)",
        cell: |s| format!("{:.4} / {:.4}", s.swimming_px.mean, s.swimming_px.p99),
    },
];

fn cells<T>(columns: &[Column<T>], rows: &[T]) -> (Vec<&'static str>, Vec<Vec<String>>) {
    let headers = columns.iter().map(|c| c.header).collect();
    let body = rows
        .iter()
        .map(|r| columns.iter().map(|c| (c.cell)(r)).collect())
        .collect();
    (headers, body)
}

/// Aligned plain text (first column left-aligned, the others right-aligned).
pub fn text<T>(columns: &[Column<T>], rows: &[T]) -> String {
    let (headers, body) = cells(columns, rows);
    let widths: Vec<usize> = (0..headers.len())
        .map(|i| {
            body.iter()
                .map(|r| r[i].chars().count())
                .chain([headers[i].chars().count()])
                .max()
                .unwrap_or(0)
        })
        .collect();
    let line = |row: Vec<&str>| {
        let mut out = String::new();
        for (i, cell) in row.iter().enumerate() {
            if i == 0 {
                out.push_str(&format!("{cell:<w$}", w = widths[i]));
            } else {
                out.push_str(&format!("  {cell:>w$}", w = widths[i]));
            }
        }
        out.trim_end().to_string() + "\n"
    };
    let mut out = line(headers);
    for r in &body {
        out.push_str(&line(r.iter().map(String::as_str).collect()));
    }
    out
}

/// A Markdown table.
pub fn markdown<T>(columns: &[Column<T>], rows: &[T]) -> String {
    let (headers, body) = cells(columns, rows);
    let mut out = format!(
        "| {} |\n|{}\n",
        headers.join(" | "),
        "---|".repeat(headers.len())
    );
    for r in body {
        out.push_str(&format!("| {} |\n", r.join(" | ")));
    }
    out
}
