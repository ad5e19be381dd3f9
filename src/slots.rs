//! Indices of the frame loop that must not mix: a **frame slot** is one of the N frames in
//! flight (command buffer, targets, readback, staging); a **view slot** is one camera of one
//! frame slot (uniforms, set 0, a method's per-view buffers, a clipmap quadtree).
//!
//! Both are newtypes over `usize`, so passing one where the other is expected does not compile;
//! [`SlotLayout`] is the one place that maps (frame slot, view) to a view slot.

/// One of the frames in flight (`frame index % frames_in_flight`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct FrameSlot(pub usize);

/// One camera of one frame slot: `frame slot * views + view` (see [`SlotLayout::view_slot`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ViewSlot(pub usize);

impl FrameSlot {
    pub fn index(self) -> usize {
        self.0
    }
}

impl ViewSlot {
    pub fn index(self) -> usize {
        self.0
    }
}

/// How many frame slots and views per frame a renderer has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SlotLayout {
    pub frames_in_flight: usize,
    pub views: usize,
}

impl SlotLayout {
    /// View slots in all (what per-view state is allocated for).
    pub fn view_slots(self) -> usize {
        self.frames_in_flight * self.views
    }

    /// The slot of frame `index`.
    pub fn frame_slot(self, index: u64) -> FrameSlot {
        FrameSlot((index % self.frames_in_flight as u64) as usize)
    }

    /// View `view` of frame slot `frame`.
    pub fn view_slot(self, frame: FrameSlot, view: usize) -> ViewSlot {
        debug_assert!(view < self.views && frame.0 < self.frames_in_flight);
        ViewSlot(frame.0 * self.views + view)
    }

    /// The view slots of frame slot `frame`, in view order.
    pub fn view_slots_of(self, frame: FrameSlot) -> impl Iterator<Item = ViewSlot> {
        (0..self.views).map(move |v| self.view_slot(frame, v))
    }

    /// Every frame slot.
    pub fn frame_slots(self) -> impl Iterator<Item = FrameSlot> {
        (0..self.frames_in_flight).map(FrameSlot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn view_slots_of_different_frames_never_collide() {
        let layout = SlotLayout {
            frames_in_flight: 3,
            views: 4,
        };
        let mut seen = std::collections::HashSet::new();
        for f in layout.frame_slots() {
            for v in layout.view_slots_of(f) {
                assert!(v.0 < layout.view_slots());
                assert!(seen.insert(v), "{f:?} reuses {v:?}");
            }
        }
        assert_eq!(seen.len(), layout.view_slots());
        assert_eq!(layout.frame_slot(7), FrameSlot(1));
    }
}
