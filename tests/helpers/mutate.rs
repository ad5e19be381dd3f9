//! Hostile segments for the reader fuzzers (tests/ring.rs, benches/ring_fuzz.rs): a valid ring
//! with a few frames, mutated the way a corrupt or malicious file would be. The C and Python
//! fuzzers (tests/helpers/ring_fuzz.c, ring_fuzz.py) apply the same strategies.

/// xorshift64*: deterministic per seed, no dependency.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
}

/// Values that sit on the edges of every check.
const INTERESTING: [u32; 18] = [
    0,
    1,
    2,
    3,
    4,
    63,
    64,
    65,
    255,
    256,
    4095,
    4096,
    8192,
    16384,
    16385,
    65536,
    0x4000_0001,
    u32::MAX,
];

fn interesting(r: &mut Rng) -> u32 {
    if r.below(4) == 0 {
        r.next() as u32
    } else {
        INTERESTING[r.below(INTERESTING.len() as u64) as usize]
    }
}

fn put32(b: &mut [u8], off: usize, v: u32) {
    if off + 4 <= b.len() {
        b[off..off + 4].copy_from_slice(&v.to_le_bytes());
    }
}

fn put64(b: &mut [u8], off: usize, v: u64) {
    if off + 8 <= b.len() {
        b[off..off + 8].copy_from_slice(&v.to_le_bytes());
    }
}

fn get32(b: &[u8], off: usize) -> u32 {
    u32::from_le_bytes(b[off..off + 4].try_into().unwrap())
}

/// One hostile variant of `template` (a valid segment).
pub fn mutate(template: &[u8], r: &mut Rng) -> Vec<u8> {
    let mut b = template.to_vec();
    let header_size = get32(template, 12) as usize;
    let slot_size = get32(template, 48) as usize;
    let slots = get32(template, 40) as usize;
    let slot = |i: usize| header_size + (i % slots.max(1)) * slot_size;
    let rounds = 1 + r.below(3);
    for _ in 0..rounds {
        match r.below(6) {
            // A header field (magic .. producer_pid, flags).
            0 => {
                let off = [8, 12, 24, 28, 32, 36, 40, 44, 48, 52, 56, 60, 76][r.below(13) as usize];
                let v = interesting(r);
                put32(&mut b, off, v);
            }
            // A slot's metadata disagreeing with the header (width, height, row_stride).
            1 => {
                let base = slot(r.below(slots as u64) as usize) + 64;
                let off = base + [24, 28, 32][r.below(3) as usize];
                let v = interesting(r);
                put32(&mut b, off, v);
            }
            // Sequence words and `latest`: odd, even, huge, pointing at any slot.
            2 => {
                let s = slot(r.below(slots as u64) as usize);
                let v = r.next() >> r.below(64);
                if r.below(2) == 0 {
                    put64(&mut b, s, v);
                } else {
                    put64(&mut b, 64, v);
                }
                let f = r.below(8);
                put64(&mut b, s + 64, f);
            }
            // Random bytes anywhere in the first page and the first slot header.
            3 => {
                for _ in 0..1 + r.below(16) {
                    let hot = [0usize, slot(0), slot(1)][r.below(3) as usize];
                    let i = (hot + r.below(320) as usize).min(b.len().saturating_sub(1));
                    if !b.is_empty() {
                        b[i] = r.next() as u8;
                    }
                }
            }
            // Truncated or padded.
            4 => {
                let len = r.below(template.len() as u64 * 2 + 1) as usize;
                b.resize(len, 0);
            }
            // A self-consistent but lying geometry: bigger frame, same file.
            _ => {
                let w = interesting(r);
                put32(&mut b, 24, w);
                put32(&mut b, 36, w.wrapping_mul(4));
            }
        }
    }
    b
}
