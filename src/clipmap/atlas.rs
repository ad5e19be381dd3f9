//! The node atlas on the CPU side: which node lives in which layer, LRU reuse of layers no view
//! wants any more, and a CPU copy of every resident node's heights (for `sample_height`).
//!
//! Fixed capacity: when every layer holds a wanted node, a new node is refused (the caller
//! counts it as deferred) instead of growing or panicking.

use std::collections::HashMap;

use super::NodeKey;

/// Layer bookkeeping of the atlas.
#[derive(Debug)]
pub struct Atlas {
    side: u32,
    slots: Vec<Option<NodeKey>>,
    /// Frame in which the layer's node was last wanted by some view (LRU key).
    last_wanted: Vec<u64>,
    /// Layers never evicted (the root level, so every lookup has a resident ancestor).
    pinned: Vec<bool>,
    /// Heights of each layer, `side x side`, row 0 = south (empty when free).
    data: Vec<Vec<f32>>,
    index: HashMap<NodeKey, u16>,
    pub evictions: u64,
}

impl Atlas {
    /// `capacity` layers of `side x side` texels (`capacity` <= 65535 is checked by the caller).
    pub fn new(capacity: u32, side: u32) -> Self {
        let n = capacity as usize;
        Atlas {
            side,
            slots: vec![None; n],
            last_wanted: vec![0; n],
            pinned: vec![false; n],
            data: vec![Vec::new(); n],
            index: HashMap::new(),
            evictions: 0,
        }
    }

    pub fn capacity(&self) -> u32 {
        self.slots.len() as u32
    }

    pub fn resident(&self) -> usize {
        self.index.len()
    }

    pub fn layer_of(&self, key: NodeKey) -> Option<u16> {
        self.index.get(&key).copied()
    }

    /// Marks a resident node as wanted in `frame` (refreshes its LRU position).
    pub fn touch(&mut self, key: NodeKey, frame: u64) {
        if let Some(&l) = self.index.get(&key) {
            self.last_wanted[l as usize] = frame;
        }
    }

    /// A layer for `key`: a free one, else the least recently wanted layer not wanted in
    /// `frame` and not pinned (its node is evicted). `None` when every layer is in use.
    pub fn allocate(&mut self, key: NodeKey, frame: u64, pinned: bool) -> Option<u16> {
        if let Some(l) = self.layer_of(key) {
            return Some(l);
        }
        let free = self.slots.iter().position(Option::is_none);
        let layer = match free {
            Some(l) => l,
            None => {
                let victim = (0..self.slots.len())
                    .filter(|&l| !self.pinned[l] && self.last_wanted[l] < frame)
                    .min_by_key(|&l| self.last_wanted[l])?;
                if let Some(old) = self.slots[victim].take() {
                    self.index.remove(&old);
                }
                self.evictions += 1;
                victim
            }
        };
        self.slots[layer] = Some(key);
        self.last_wanted[layer] = frame;
        self.pinned[layer] = pinned;
        self.data[layer].clear();
        self.index.insert(key, layer as u16);
        Some(layer as u16)
    }

    /// Stores the CPU copy of a layer's heights (`side x side`).
    pub fn store(&mut self, layer: u16, heights: Vec<f32>) {
        debug_assert_eq!(heights.len(), (self.side * self.side) as usize);
        self.data[layer as usize] = heights;
    }

    /// Height texel `(i, j)` of a layer (0 for an empty layer; lookups never reach one).
    pub fn texel(&self, layer: u16, i: u32, j: u32) -> f32 {
        self.data[layer as usize]
            .get((j * self.side + i) as usize)
            .copied()
            .unwrap_or(0.0)
    }
}
