//! The chunked-clipmap node pyramid: addressing, the level writer and the node reader.
//!
//! Level `lod` holds a virtual raster `R_lod` of `ceil(width / 2^lod) x ceil(height / 2^lod)`
//! valid samples (row 0 = south). `R_0` is the (void-filled) source; `R_{l+1}` texel `(u, v)`
//! is the 2x2 box average of `R_l` texels `(2u..2u+1, 2v..2v+1)` (indices clamped to the
//! padded level). The level is cut into `nodes_x x nodes_y` nodes of `center` texels; node
//! `(x, y)` texel `(i, j)`, `i, j` in `[-border, center + border)`, is
//! `R_lod[clamp(x*center + i), clamp(y*center + j)]` where clamping keeps the index inside the
//! level (so borders are the neighbours' centre texels, and the outer edge is replicated).
//! Texels of a node beyond the valid extent replicate the last valid row/column.
//!
//! Every record is a function of its level's raster alone, so records are built in parallel
//! (rayon), each with memory of a few records, and written at their offsets: the files are
//! the same bit for bit for any number of threads.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::os::unix::fs::FileExt;
use std::path::Path;

use rayon::prelude::*;

use crate::error::{Error, Result};

pub const LEVEL_MAGIC: &[u8; 8] = b"VKTLEVEL";
pub const LEVEL_HEADER: u64 = 64;
pub const NODE_HEADER: u64 = 16;
/// Largest level-0 side the format accepts (2^24 + 1 samples: a 16777217² level 0 would be
/// about 1 PiB of heights). Inputs claiming more are refused before anything is read.
pub const MAX_SIDE_SAMPLES: u64 = (1 << 24) + 1;
/// Version of the level file layout (independent of the manifest's).
pub const LEVEL_VERSION: u32 = 1;

/// Node layout and addressing of a pyramid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    pub width: u64,
    pub height: u64,
    pub center: u32,
    pub border: u32,
}

impl Layout {
    pub fn new(width: u64, height: u64, center: u32, border: u32) -> Result<Self> {
        if width < 2 || height < 2 || width > MAX_SIDE_SAMPLES || height > MAX_SIDE_SAMPLES {
            return Err(Error::invalid(
                "layout",
                format!("{width}x{height} samples is outside 2..={MAX_SIDE_SAMPLES} per side"),
            ));
        }
        if !(4..=8192).contains(&center) || center % 2 != 0 {
            return Err(Error::invalid(
                "--node-size",
                format!("center size {center} must be even and within 4..=8192"),
            ));
        }
        if border < 2 || border > center {
            return Err(Error::invalid(
                "--border",
                format!("border size {border} must be within 2..={center}"),
            ));
        }
        Ok(Layout {
            width,
            height,
            center,
            border,
        })
    }

    /// Texels per node side, borders included.
    pub fn side(&self) -> u32 {
        self.center + 2 * self.border
    }

    /// Valid samples of level `lod`.
    pub fn level_size(&self, lod: u32) -> (u64, u64) {
        let d = |n: u64| {
            if lod >= 64 {
                1
            } else {
                n.div_ceil(1u64 << lod)
            }
        };
        (d(self.width), d(self.height))
    }

    /// Nodes of level `lod`.
    pub fn nodes(&self, lod: u32) -> (u32, u32) {
        let (w, h) = self.level_size(lod);
        (
            w.div_ceil(self.center as u64) as u32,
            h.div_ceil(self.center as u64) as u32,
        )
    }

    /// Number of levels: down to the first level that is a single node.
    pub fn levels(&self) -> u32 {
        let mut l = 0;
        while self.nodes(l) != (1, 1) {
            l += 1;
        }
        l + 1
    }

    /// For a texel index `i` in `[-border, center + border)` of node `x` (one axis) at a level
    /// with `nodes` nodes on that axis: the node and centre texel it is read from.
    pub fn source_of(&self, nodes: u32, x: u32, i: i64) -> (u32, u32) {
        let c = self.center as i64;
        let g = (x as i64 * c + i).clamp(0, nodes as i64 * c - 1);
        ((g / c) as u32, (g % c) as u32)
    }

    /// Bytes of one node record.
    pub fn record_size(&self, layers: LayerSet) -> u64 {
        let t = (self.side() as u64).pow(2);
        NODE_HEADER
            + t * 4
            + if layers.mask { t } else { 0 }
            + if layers.albedo { t * 4 } else { 0 }
    }

    /// Byte offset of node `(x, y)` in its level file.
    pub fn record_offset(&self, lod: u32, x: u32, y: u32, layers: LayerSet) -> u64 {
        let (nx, _) = self.nodes(lod);
        LEVEL_HEADER + (y as u64 * nx as u64 + x as u64) * self.record_size(layers)
    }
}

/// Which optional layers the records carry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct LayerSet {
    pub mask: bool,
    pub albedo: bool,
}

/// Texels of a rectangle (row-major, row 0 = south); empty vectors for absent layers.
#[derive(Clone, Debug, Default)]
pub struct Block {
    pub heights: Vec<f32>,
    pub mask: Vec<u8>,
    pub rgba: Vec<u8>,
}

/// One node record as stored: `side x side` texels including borders.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    pub min: f32,
    pub max: f32,
    /// Filled (void) texels among the centre texels.
    pub filled: u32,
    pub heights: Vec<f32>,
    pub mask: Vec<u8>,
    pub rgba: Vec<u8>,
}

impl Node {
    /// Centre texel `(i, j)` of a node with the given layout.
    pub fn centre(&self, layout: &Layout, i: u32, j: u32) -> f32 {
        let s = layout.side() as usize;
        let b = layout.border as usize;
        self.heights[(j as usize + b) * s + i as usize + b]
    }
}

/// Source of level-0 texels (the void-filled raster, the procedural generator, ...). Records
/// are built on rayon's threads, hence `Sync`.
pub trait LeafSource: Sync {
    /// Texels at level-0 samples `(cols[i], rows[j])` (already clamped to the grid), row-major
    /// with rows outer, into `out` (cleared first): heights, plus the mask and RGBA of the
    /// layers in `layers`.
    fn texels(&self, cols: &[u64], rows: &[u64], layers: LayerSet, out: &mut Block) -> Result<()>;
}

/// Where a level's texels come from.
pub enum LevelInput<'a> {
    /// Level 0.
    Leaves(&'a dyn LeafSource),
    /// The next finer level's file (2x2 box averages of its texels).
    Child(&'a Path),
}

/// Per-level statistics from the writer.
#[derive(Clone, Copy, Debug, Default)]
pub struct LevelStats {
    pub nodes: u64,
    pub bytes: u64,
    pub min: f32,
    pub max: f32,
    pub filled: u64,
}

/// The 64-byte header of level `lod`'s file.
pub fn level_header(layout: &Layout, lod: u32, layers: LayerSet) -> Vec<u8> {
    let (nx, ny) = layout.nodes(lod);
    let mut h = Vec::with_capacity(LEVEL_HEADER as usize);
    h.extend_from_slice(LEVEL_MAGIC);
    for v in [
        LEVEL_VERSION,
        lod,
        nx,
        ny,
        layout.center,
        layout.border,
        layers.mask as u32 | (layers.albedo as u32) << 1,
    ] {
        h.extend_from_slice(&v.to_le_bytes());
    }
    h.extend_from_slice(&layout.record_size(layers).to_le_bytes());
    h.resize(LEVEL_HEADER as usize, 0);
    h
}

/// Level-`lod` sample indices of a node's texels on one axis: `x*center + i - border`,
/// `i` in `0..side`, clamped to the level's valid samples `0..n`.
fn texel_indices(layout: &Layout, x: u32, n: u64) -> Vec<u64> {
    let c = layout.center as i64;
    (0..layout.side() as i64)
        .map(|i| (x as i64 * c + i - layout.border as i64).clamp(0, n as i64 - 1) as u64)
        .collect()
}

/// Scratch buffers of one worker.
#[derive(Default)]
struct Scratch {
    block: Block,
    rect: Block,
    io: Vec<u8>,
    record: Vec<u8>,
}

/// Writes level `lod` to `path`: every record built from `input` in parallel and written at its
/// offset; the file is fsynced. `progress(n)` counts finished nodes.
pub fn write_level(
    path: &Path,
    layout: &Layout,
    lod: u32,
    layers: LayerSet,
    input: LevelInput<'_>,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<LevelStats> {
    let (nx, ny) = layout.nodes(lod);
    let size = layout.record_size(layers);
    let bytes = LEVEL_HEADER + nx as u64 * ny as u64 * size;
    let file = File::create(path).map_err(|e| Error::io(path, e))?;
    file.write_all_at(&level_header(layout, lod, layers), 0)
        .map_err(|e| Error::io(path, e))?;
    let child = match input {
        LevelInput::Child(p) => Some((File::open(p).map_err(|e| Error::io(p, e))?, p)),
        LevelInput::Leaves(_) => None,
    };
    let identity = || (f32::INFINITY, f32::NEG_INFINITY, 0u64);
    let (min, max, filled) = (0..nx as u64 * ny as u64)
        .into_par_iter()
        .map_init(Scratch::default, |s, i| -> Result<(f32, f32, u64)> {
            let (x, y) = ((i % nx as u64) as u32, (i / nx as u64) as u32);
            match (&input, &child) {
                (LevelInput::Leaves(leaves), _) => {
                    let (w, h) = layout.level_size(0);
                    let cols = texel_indices(layout, x, w);
                    let rows = texel_indices(layout, y, h);
                    leaves.texels(&cols, &rows, layers, &mut s.block)?;
                }
                (LevelInput::Child(_), Some((f, p))) => {
                    parent_texels(f, p, layout, lod, layers, x, y, s)?;
                }
                _ => unreachable!("a child file for every child input"),
            }
            let summary = encode_record(layout, layers, &s.block, &mut s.record);
            file.write_all_at(&s.record, layout.record_offset(lod, x, y, layers))
                .map_err(|e| Error::io(path, e))?;
            progress(1);
            Ok(summary)
        })
        .try_reduce(identity, |a, b| Ok((a.0.min(b.0), a.1.max(b.1), a.2 + b.2)))?;
    file.sync_all().map_err(|e| Error::io(path, e))?;
    Ok(LevelStats {
        nodes: nx as u64 * ny as u64,
        bytes,
        min,
        max,
        filled,
    })
}

/// Serialises a record from its `side x side` texels: `(min, max, filled centre texels)`.
fn encode_record(
    layout: &Layout,
    layers: LayerSet,
    block: &Block,
    out: &mut Vec<u8>,
) -> (f32, f32, u64) {
    let (lo, hi) = block
        .heights
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let (s, b, c) = (
        layout.side() as usize,
        layout.border as usize,
        layout.center as usize,
    );
    let filled = if layers.mask {
        (b..b + c)
            .map(|j| {
                block.mask[j * s + b..j * s + b + c]
                    .iter()
                    .filter(|&&m| m != 0)
                    .count()
            })
            .sum::<usize>() as u32
    } else {
        0
    };
    out.clear();
    out.extend_from_slice(&lo.to_le_bytes());
    out.extend_from_slice(&hi.to_le_bytes());
    out.extend_from_slice(&filled.to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes());
    for v in &block.heights {
        out.extend_from_slice(&v.to_le_bytes());
    }
    if layers.mask {
        out.extend_from_slice(&block.mask);
    }
    if layers.albedo {
        out.extend_from_slice(&block.rgba);
    }
    (lo, hi, filled as u64)
}

/// Reads the level-`lod` texels `cols x rows` (`cols = c0..=c1`, `rows = r0..=r1`, valid
/// samples) from the centre regions of the level file's nodes into `s.rect`: one read of the
/// needed rows per node and layer.
#[allow(clippy::too_many_arguments)]
fn read_rect(
    file: &File,
    path: &Path,
    layout: &Layout,
    lod: u32,
    layers: LayerSet,
    (c0, c1): (u64, u64),
    (r0, r1): (u64, u64),
    s: &mut Scratch,
) -> Result<()> {
    let (c, b, side) = (
        layout.center as u64,
        layout.border as u64,
        layout.side() as u64,
    );
    let (rw, rh) = ((c1 - c0 + 1) as usize, (r1 - r0 + 1) as usize);
    let rect = &mut s.rect;
    rect.heights.resize(rw * rh, 0.0);
    rect.mask.resize(if layers.mask { rw * rh } else { 0 }, 0);
    rect.rgba
        .resize(if layers.albedo { rw * rh * 4 } else { 0 }, 0);
    let t = side * side;
    for ky in r0 / c..=r1 / c {
        for kx in c0 / c..=c1 / c {
            let (j0, j1) = (r0.max(ky * c) - ky * c, r1.min(ky * c + c - 1) - ky * c);
            let (i0, i1) = (c0.max(kx * c) - kx * c, c1.min(kx * c + c - 1) - kx * c);
            let rec = layout.record_offset(lod, kx as u32, ky as u32, layers);
            let rows = (j1 - j0 + 1) as usize;
            // (layer offset in the record, bytes per texel)
            let mut planes = vec![(NODE_HEADER, 4u64)];
            if layers.mask {
                planes.push((NODE_HEADER + t * 4, 1));
            }
            if layers.albedo {
                planes.push((NODE_HEADER + t * (4 + layers.mask as u64), 4));
            }
            for (k, &(plane, bpt)) in planes.iter().enumerate() {
                let row_bytes = (side * bpt) as usize;
                s.io.resize(rows * row_bytes, 0);
                let at = rec + plane + (j0 + b) * side * bpt;
                file.read_exact_at(&mut s.io, at).map_err(|e| {
                    Error::invalid(
                        path.display().to_string(),
                        format!(
                            "node ({kx}, {ky}) of level {lod} unreadable (truncated file?): {e}"
                        ),
                    )
                })?;
                for jj in 0..rows {
                    let dst_row = (ky * c + j0 + jj as u64 - r0) as usize;
                    let dst = dst_row * rw + (kx * c + i0 - c0) as usize;
                    let src = &s.io[jj * row_bytes + ((i0 + b) * bpt) as usize
                        ..jj * row_bytes + ((i1 + b + 1) * bpt) as usize];
                    let n = (i1 - i0 + 1) as usize;
                    match (k, bpt) {
                        (0, _) => {
                            for (o, v) in rect.heights[dst..dst + n]
                                .iter_mut()
                                .zip(src.chunks_exact(4))
                            {
                                *o = f32::from_le_bytes([v[0], v[1], v[2], v[3]]);
                            }
                        }
                        (_, 1) => rect.mask[dst..dst + n].copy_from_slice(src),
                        _ => rect.rgba[dst * 4..(dst + n) * 4].copy_from_slice(src),
                    }
                }
            }
        }
    }
    Ok(())
}

/// Texels of node `(x, y)` at level `lod >= 1` (borders included) into `s.block`: texel `u`
/// is the 2x2 box `((a + b) + (c + d)) * 0.25` (f32) of child texels `2u, 2u + 1` (clamped to
/// the child level's valid samples), the mask the max of the four, albedo their rounded mean;
/// `u` itself is clamped to the level's valid samples (the padding replicates the last one).
#[allow(clippy::too_many_arguments)]
fn parent_texels(
    child: &File,
    child_path: &Path,
    layout: &Layout,
    lod: u32,
    layers: LayerSet,
    x: u32,
    y: u32,
    s: &mut Scratch,
) -> Result<()> {
    let (w, h) = layout.level_size(lod);
    let (cw, ch) = layout.level_size(lod - 1);
    let cols = texel_indices(layout, x, w);
    let rows = texel_indices(layout, y, h);
    let span = |v: &[u64], n: u64| (2 * v[0], (2 * v[v.len() - 1] + 1).min(n - 1));
    let (c0, c1) = span(&cols, cw);
    let (r0, r1) = span(&rows, ch);
    read_rect(
        child,
        child_path,
        layout,
        lod - 1,
        layers,
        (c0, c1),
        (r0, r1),
        s,
    )?;
    let rw = (c1 - c0 + 1) as usize;
    let at = |g: u64, n: u64, o: u64| (g.min(n - 1) - o) as usize;
    let (rect, out) = (&s.rect, &mut s.block);
    out.heights.clear();
    out.mask.clear();
    out.rgba.clear();
    for &v in &rows {
        let (ya, yb) = (at(2 * v, ch, r0), at(2 * v + 1, ch, r0));
        for &u in &cols {
            let (xa, xb) = (at(2 * u, cw, c0), at(2 * u + 1, cw, c0));
            let k = [ya * rw + xa, ya * rw + xb, yb * rw + xa, yb * rw + xb];
            let hv = |i: usize| rect.heights[k[i]];
            out.heights.push(((hv(0) + hv(1)) + (hv(2) + hv(3))) * 0.25);
            if layers.mask {
                out.mask
                    .push(k.iter().map(|&i| rect.mask[i]).max().unwrap_or(0));
            }
            if layers.albedo {
                for ch in 0..4 {
                    let sum: u32 = k.iter().map(|&i| rect.rgba[i * 4 + ch] as u32).sum();
                    out.rgba.push(((sum + 2) / 4) as u8);
                }
            }
        }
    }
    Ok(())
}

/// Full rows of level 0 straight from a level file (positioned reads, no shared state): the
/// source of the tile statistics while preprocessing and when a grid size was not stored.
pub struct LevelRows {
    file: File,
    path: std::path::PathBuf,
    layout: Layout,
    layers: LayerSet,
    spacing: f64,
}

impl LevelRows {
    pub fn open(path: &Path, layout: Layout, layers: LayerSet, spacing: f64) -> Result<Self> {
        if layout.width > u32::MAX as u64 || layout.height > u32::MAX as u64 {
            return Err(Error::invalid(
                path.display().to_string(),
                "level 0 is too large for row access",
            ));
        }
        Ok(LevelRows {
            file: File::open(path).map_err(|e| Error::io(path, e))?,
            path: path.to_path_buf(),
            layout,
            layers,
            spacing,
        })
    }
}

impl super::Level0 for LevelRows {
    fn width(&self) -> u32 {
        self.layout.width as u32
    }
    fn height(&self) -> u32 {
        self.layout.height as u32
    }
    fn spacing(&self) -> f64 {
        self.spacing
    }
    fn sample(&self, col: u32, row: u32) -> Result<f32> {
        let mut v = Vec::with_capacity(1);
        self.row(row, col, col, &mut v)?;
        Ok(v[0])
    }
    /// One positioned read per node the row crosses; non-finite heights are errors.
    fn row(&self, row: u32, col0: u32, col1: u32, out: &mut Vec<f32>) -> Result<()> {
        let l = &self.layout;
        if row as u64 >= l.height || col1 as u64 >= l.width || col0 > col1 {
            return Err(Error::invalid(
                self.path.display().to_string(),
                format!("row {row} columns {col0}..={col1} outside the level"),
            ));
        }
        let (c, b, side) = (l.center as u64, l.border as u64, l.side() as u64);
        let (ky, j) = (row as u64 / c, row as u64 % c);
        out.clear();
        let mut buf = Vec::new();
        for kx in col0 as u64 / c..=col1 as u64 / c {
            let i0 = (col0 as u64).max(kx * c) - kx * c;
            let i1 = (col1 as u64).min(kx * c + c - 1) - kx * c;
            buf.resize(((i1 - i0 + 1) * 4) as usize, 0);
            let at = l.record_offset(0, kx as u32, ky as u32, self.layers)
                + NODE_HEADER
                + ((j + b) * side + i0 + b) * 4;
            self.file.read_exact_at(&mut buf, at).map_err(|e| {
                Error::invalid(
                    self.path.display().to_string(),
                    format!("node ({kx}, {ky}) unreadable (truncated file?): {e}"),
                )
            })?;
            for v in buf.chunks_exact(4) {
                let h = f32::from_le_bytes([v[0], v[1], v[2], v[3]]);
                if !h.is_finite() {
                    return Err(Error::invalid(
                        format!("{} node 0/{kx}/{ky}", self.path.display()),
                        format!("height {h} is not finite: corrupt node"),
                    ));
                }
                out.push(h);
            }
        }
        Ok(())
    }
}

/// Reads node `(x, y)` of the level file `file` (already opened) alone: one seek, one read.
pub fn read_node_from(
    file: &mut File,
    path: &Path,
    layout: &Layout,
    lod: u32,
    layers: LayerSet,
    x: u32,
    y: u32,
) -> Result<Node> {
    let (nx, ny) = layout.nodes(lod);
    if x >= nx || y >= ny {
        return Err(Error::invalid(
            path.display().to_string(),
            format!("node ({x}, {y}) outside level {lod} ({nx}x{ny} nodes)"),
        ));
    }
    let size = layout.record_size(layers) as usize;
    let mut buf = vec![0u8; size];
    file.seek(SeekFrom::Start(layout.record_offset(lod, x, y, layers)))
        .map_err(|e| Error::io(path, e))?;
    file.read_exact(&mut buf).map_err(|e| {
        Error::invalid(
            path.display().to_string(),
            format!("node ({x}, {y}) of level {lod} unreadable (truncated file?): {e}"),
        )
    })?;
    parse_record(&buf, layout, layers).map_err(|e| {
        Error::invalid(
            path.display().to_string(),
            format!("node ({x}, {y}) of level {lod}: {e}"),
        )
    })
}

/// One record's bytes as a [`Node`]: exactly `record_size` bytes; heights are returned as
/// stored (readers check them: `Geometry::check`, the level-0 reader).
pub fn parse_record(buf: &[u8], layout: &Layout, layers: LayerSet) -> Result<Node> {
    let size = layout.record_size(layers) as usize;
    if buf.len() != size {
        return Err(Error::invalid(
            "node record",
            format!("{} bytes, expected {size}", buf.len()),
        ));
    }
    let f = |o: usize| f32::from_le_bytes(buf[o..o + 4].try_into().expect("4 bytes"));
    let t = (layout.side() as usize).pow(2);
    let h0 = NODE_HEADER as usize;
    let heights = (0..t).map(|i| f(h0 + i * 4)).collect();
    let mut o = h0 + t * 4;
    let mask = if layers.mask {
        o += t;
        buf[o - t..o].to_vec()
    } else {
        Vec::new()
    };
    let rgba = if layers.albedo {
        buf[o..o + t * 4].to_vec()
    } else {
        Vec::new()
    };
    Ok(Node {
        min: f(0),
        max: f(4),
        filled: u32::from_le_bytes(buf[8..12].try_into().expect("4 bytes")),
        heights,
        mask,
        rgba,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_and_nodes() {
        let l = Layout::new(1025, 1025, 256, 2).unwrap();
        assert_eq!(l.nodes(0), (5, 5));
        assert_eq!(l.level_size(1), (513, 513));
        assert_eq!(l.nodes(1), (3, 3));
        assert_eq!(l.nodes(2), (2, 2));
        assert_eq!(l.nodes(3), (1, 1));
        assert_eq!(l.levels(), 4);
        assert_eq!(l.source_of(5, 0, -2), (0, 0));
        assert_eq!(l.source_of(5, 1, -1), (0, 255));
        assert_eq!(l.source_of(5, 4, 257), (4, 255));
    }
}
