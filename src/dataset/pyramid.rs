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

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::Path;

use crate::error::{Error, Result};

pub const LEVEL_MAGIC: &[u8; 8] = b"VKTLEVEL";
pub const LEVEL_HEADER: u64 = 64;
pub const NODE_HEADER: u64 = 16;

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
        if width < 2 || height < 2 {
            return Err(Error::invalid(
                "layout",
                format!("{width}x{height} samples is smaller than 2x2"),
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

/// The centre texels of one node (`center x center`, row 0 = south); empty vectors for absent
/// layers.
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

    fn centre_block(&self, layout: &Layout) -> Block {
        let (s, b, c) = (
            layout.side() as usize,
            layout.border as usize,
            layout.center as usize,
        );
        let mut out = Block::default();
        for j in 0..c {
            let r = (j + b) * s + b;
            out.heights.extend_from_slice(&self.heights[r..r + c]);
            if !self.mask.is_empty() {
                out.mask.extend_from_slice(&self.mask[r..r + c]);
            }
            if !self.rgba.is_empty() {
                out.rgba.extend_from_slice(&self.rgba[r * 4..(r + c) * 4]);
            }
        }
        out
    }
}

/// Source of level-0 centre blocks.
pub trait LeafSource {
    /// Fills `out` with node `(x, y)`'s centre texels: sample `(x*c + i, y*c + j)` clamped to
    /// the level-0 extent.
    fn leaf(&self, x: u32, y: u32, out: &mut Block) -> Result<()>;
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

fn write_header(w: &mut impl Write, layout: &Layout, lod: u32, layers: LayerSet) -> Result<()> {
    let (nx, ny) = layout.nodes(lod);
    let mut h = Vec::with_capacity(LEVEL_HEADER as usize);
    h.extend_from_slice(LEVEL_MAGIC);
    for v in [
        super::manifest::VERSION,
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
    w.write_all(&h).map_err(|e| Error::io("level file", e))
}

/// Writes level `lod` to `path`, node rows south to north, taking centre blocks from
/// `centre(x, y)`; only three rows of centre blocks are held at a time.
pub fn write_level(
    path: &Path,
    layout: &Layout,
    lod: u32,
    layers: LayerSet,
    centre: &mut dyn FnMut(u32, u32) -> Result<Block>,
    progress: &mut dyn FnMut(u64),
) -> Result<LevelStats> {
    let (nx, ny) = layout.nodes(lod);
    let file = File::create(path).map_err(|e| Error::io(path, e))?;
    let mut out = BufWriter::with_capacity(1 << 20, file);
    write_header(&mut out, layout, lod, layers)?;
    let (s, c, b) = (
        layout.side() as usize,
        layout.center as usize,
        layout.border as i64,
    );
    let cols: Vec<Vec<(u32, u32)>> = (0..nx)
        .map(|x| {
            (0..s as i64)
                .map(|i| layout.source_of(nx, x, i - b))
                .collect()
        })
        .collect();
    let mut rows: Vec<(u32, Vec<Block>)> = Vec::new();
    let mut stats = LevelStats {
        min: f32::INFINITY,
        max: f32::NEG_INFINITY,
        ..Default::default()
    };
    let mut rec = Vec::with_capacity(layout.record_size(layers) as usize);
    for y in 0..ny {
        rows.retain(|(r, _)| *r + 1 >= y);
        for r in y.saturating_sub(1)..=(y + 1).min(ny - 1) {
            if !rows.iter().any(|(rr, _)| *rr == r) {
                let blocks = (0..nx).map(|x| centre(x, r)).collect::<Result<Vec<_>>>()?;
                rows.push((r, blocks));
            }
        }
        let row_srcs: Vec<(u32, u32)> = (0..s as i64)
            .map(|j| layout.source_of(ny, y, j - b))
            .collect();
        for (x, col_srcs) in cols.iter().enumerate() {
            let mut heights = Vec::with_capacity(s * s);
            let mut mask = Vec::new();
            let mut rgba = Vec::new();
            for &(ry, cj) in &row_srcs {
                let row = &rows.iter().find(|(r, _)| *r == ry).expect("row cached").1;
                for &(rx, ci) in col_srcs {
                    let blk = &row[rx as usize];
                    let k = cj as usize * c + ci as usize;
                    heights.push(blk.heights[k]);
                    if layers.mask {
                        mask.push(blk.mask[k]);
                    }
                    if layers.albedo {
                        rgba.extend_from_slice(&blk.rgba[k * 4..k * 4 + 4]);
                    }
                }
            }
            let (lo, hi) = heights
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                    (lo.min(v), hi.max(v))
                });
            let own = &rows.iter().find(|(r, _)| *r == y).expect("row cached").1[x];
            let filled = own.mask.iter().filter(|&&m| m != 0).count() as u32;
            stats.min = stats.min.min(lo);
            stats.max = stats.max.max(hi);
            stats.filled += filled as u64;
            rec.clear();
            rec.extend_from_slice(&lo.to_le_bytes());
            rec.extend_from_slice(&hi.to_le_bytes());
            rec.extend_from_slice(&filled.to_le_bytes());
            rec.extend_from_slice(&0u32.to_le_bytes());
            for v in &heights {
                rec.extend_from_slice(&v.to_le_bytes());
            }
            rec.extend_from_slice(&mask);
            rec.extend_from_slice(&rgba);
            out.write_all(&rec).map_err(|e| Error::io(path, e))?;
            stats.nodes += 1;
            progress(1);
        }
    }
    out.flush().map_err(|e| Error::io(path, e))?;
    out.get_ref().sync_all().map_err(|e| Error::io(path, e))?;
    stats.bytes = LEVEL_HEADER + stats.nodes * layout.record_size(layers);
    Ok(stats)
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

/// Parent centre block of node `(x, y)` at level `lod >= 1` from its children at `lod - 1`
/// (read from that level's file): 2x2 box average `((a + b) + (c + d)) * 0.25` in f32 over the
/// valid extent, then the padding replicated from the last valid texel.
pub fn parent_block(
    child_file: &mut File,
    child_path: &Path,
    layout: &Layout,
    lod: u32,
    layers: LayerSet,
    x: u32,
    y: u32,
) -> Result<Block> {
    let (cnx, cny) = layout.nodes(lod - 1);
    let c = layout.center as usize;
    let mut kids: [[Option<Block>; 2]; 2] = Default::default();
    for (dy, row) in kids.iter_mut().enumerate() {
        for (dx, k) in row.iter_mut().enumerate() {
            let (kx, ky) = (2 * x + dx as u32, 2 * y + dy as u32);
            if kx < cnx && ky < cny {
                let n = read_node_from(child_file, child_path, layout, lod - 1, layers, kx, ky)?;
                *k = Some(n.centre_block(layout));
            }
        }
    }
    let (w, h) = layout.level_size(lod);
    let cx_max = cnx as u64 * c as u64 - 1;
    let cy_max = cny as u64 * c as u64 - 1;
    let texel = |gu: u64, gv: u64| -> (&Block, usize) {
        let (gu, gv) = (gu.min(cx_max), gv.min(cy_max));
        let (kx, ky) = (
            (gu / c as u64) as u32 - 2 * x,
            (gv / c as u64) as u32 - 2 * y,
        );
        let blk = kids[ky as usize][kx as usize]
            .as_ref()
            .expect("child exists for valid texels");
        (blk, (gv as usize % c) * c + gu as usize % c)
    };
    let mut out = Block {
        heights: vec![0.0; c * c],
        mask: if layers.mask {
            vec![0; c * c]
        } else {
            Vec::new()
        },
        rgba: if layers.albedo {
            vec![0; c * c * 4]
        } else {
            Vec::new()
        },
    };
    let (x0, y0) = (x as u64 * c as u64, y as u64 * c as u64);
    let vw = (w - x0).min(c as u64) as usize; // valid texels in this node
    let vh = (h - y0).min(c as u64) as usize;
    for j in 0..vh {
        for i in 0..vw {
            let (gu, gv) = (2 * (x0 + i as u64), 2 * (y0 + j as u64));
            let t = [
                texel(gu, gv),
                texel(gu + 1, gv),
                texel(gu, gv + 1),
                texel(gu + 1, gv + 1),
            ];
            let hv = |k: usize| t[k].0.heights[t[k].1];
            let o = j * c + i;
            out.heights[o] = ((hv(0) + hv(1)) + (hv(2) + hv(3))) * 0.25;
            if layers.mask {
                out.mask[o] = t.iter().map(|(b, k)| b.mask[*k]).max().unwrap_or(0);
            }
            if layers.albedo {
                for ch in 0..4 {
                    let s: u32 = t.iter().map(|(b, k)| b.rgba[k * 4 + ch] as u32).sum();
                    out.rgba[o * 4 + ch] = ((s + 2) / 4) as u8;
                }
            }
        }
    }
    pad_block(&mut out, c, vw, vh);
    Ok(out)
}

/// Replicates the last valid column/row of a `c x c` block into texels `>= vw` / `>= vh`.
pub fn pad_block(out: &mut Block, c: usize, vw: usize, vh: usize) {
    for j in 0..c {
        for i in 0..c {
            if i < vw && j < vh {
                continue;
            }
            let src = j.min(vh - 1) * c + i.min(vw - 1);
            let dst = j * c + i;
            out.heights[dst] = out.heights[src];
            if !out.mask.is_empty() {
                out.mask[dst] = out.mask[src];
            }
            if !out.rgba.is_empty() {
                for ch in 0..4 {
                    out.rgba[dst * 4 + ch] = out.rgba[src * 4 + ch];
                }
            }
        }
    }
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
