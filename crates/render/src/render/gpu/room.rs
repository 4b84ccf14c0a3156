//! Room for a count known only on the GPU (the Gaussians a level-of-detail
//! cut keeps, the tile entries of a frame), planned from the last frame's
//! count so a frame need not read it back before sizing the work after it.
//! The count itself comes back with the image; a frame it outgrew is drawn
//! again with room for it.

/// Frames after one outgrew its room that are planned with half more room
/// instead of an eighth (about a second of a moving view).
const CALM_FRAMES: u32 = 30;

/// A floor on the room beyond the count, so small counts seldom outgrow it.
const FLOOR: u32 = 4096;

/// The room of one count: planned, given to the last frame, and settled.
#[derive(Debug)]
pub(super) struct Room {
    /// Room for the next frame, from the last settled count; `None` before
    /// the first frame and where no room within `largest` would do.
    planned: Option<u32>,
    /// The room the last frame was given.
    pub given: u32,
    /// The count last settled.
    pub settled: u32,
    /// Frames settled since one outgrew its room.
    frames_since_outgrown: u32,
}

impl Default for Room {
    fn default() -> Self {
        Self {
            planned: None,
            given: 0,
            settled: 0,
            frames_since_outgrown: CALM_FRAMES,
        }
    }
}

impl Room {
    /// The room planned for this frame, if any (else the count must be read
    /// back first).
    pub fn planned(&self) -> Option<u32> {
        self.planned
    }

    /// Forgets the plan (after a failure on the GPU).
    pub fn forget(&mut self) {
        self.planned = None;
    }

    /// Forgets the plan and counts the frame as one that outgrew its room
    /// (its count was not known: another count it depends on outgrew its
    /// own room).
    pub fn outgrown(&mut self) {
        self.planned = None;
        self.frames_since_outgrown = 0;
    }

    /// Takes the frame's `count` (read back after it) and plans the next
    /// frame's room, at most `largest`; false when the count did not fit the
    /// room the frame was given.
    pub fn settle(&mut self, count: u32, largest: u32) -> bool {
        let fits = count <= self.given;
        self.settled = count;
        self.frames_since_outgrown = match fits {
            true => self.frames_since_outgrown.saturating_add(1),
            false => 0,
        };
        // An eighth more than the last count, so a turning camera seldom
        // outgrows the room; half more for a while after a frame did, so a
        // zoom or a growing window is not drawn twice frame after frame.
        // Unused room costs only idle workgroups.
        let extra = match self.frames_since_outgrown < CALM_FRAMES {
            true => count / 2,
            false => count / 8,
        };
        let room = count
            .saturating_add(extra)
            .saturating_add(FLOOR)
            .min(largest);
        self.planned = (room >= count).then_some(room);
        fits
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn room_grows_after_a_frame_outgrows_it_and_calms_down_after() {
        let mut room = Room::default();
        assert_eq!(room.planned(), None);
        room.given = 1000;
        assert!(room.settle(1000, u32::MAX));
        assert_eq!(room.planned(), Some(1000 + 125 + FLOOR));
        room.given = room.planned().unwrap();
        assert!(!room.settle(100_000, u32::MAX));
        assert_eq!(room.planned(), Some(100_000 + 50_000 + FLOOR));
        for _ in 0..CALM_FRAMES - 1 {
            room.given = room.planned().unwrap();
            assert!(room.settle(100_000, u32::MAX));
            assert_eq!(room.planned(), Some(100_000 + 50_000 + FLOOR));
        }
        room.given = room.planned().unwrap();
        assert!(room.settle(100_000, u32::MAX));
        assert_eq!(room.planned(), Some(100_000 + 12_500 + FLOOR));
    }

    #[test]
    fn no_room_is_planned_past_the_largest_sort() {
        let mut room = Room::default();
        assert!(!room.settle(5000, 6000));
        assert_eq!(room.planned(), Some(6000));
        assert!(!room.settle(7000, 6000));
        assert_eq!(room.planned(), None);
        // Counts near u32::MAX do not overflow.
        assert!(!room.settle(u32::MAX, u32::MAX));
        assert_eq!(room.planned(), Some(u32::MAX));
    }
}
