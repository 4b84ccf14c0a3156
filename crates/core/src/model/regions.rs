//! The 18 semantic regions of the head mesh and the 7 editing groups they form
//! (thesis Figure 5.2). Every triangle belongs to exactly one region; edits apply
//! to a whole group.

use serde::{Deserialize, Serialize};

/// One semantic region of the head mesh. The order is the on-disk and table order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Region {
    TeethUpper,
    TeethLower,
    Lips,
    LipsInside,
    LeftEyeRegion,
    RightEyeRegion,
    LeftEyeSocket,
    RightEyeSocket,
    LeftEyeball,
    RightEyeball,
    LeftEar,
    RightEar,
    Neck,
    Boundary,
    Hair,
    Remainder,
    Nose,
    Skin,
}

/// An editing group: a set of regions that always share one Gaussian source and
/// one shape weight vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Group {
    Mouth,
    Eyes,
    Ears,
    Neck,
    Hair,
    Nose,
    Face,
}

impl Region {
    /// Number of regions.
    pub const COUNT: usize = 18;

    /// All regions in table order.
    pub const ALL: [Region; Region::COUNT] = [
        Region::TeethUpper,
        Region::TeethLower,
        Region::Lips,
        Region::LipsInside,
        Region::LeftEyeRegion,
        Region::RightEyeRegion,
        Region::LeftEyeSocket,
        Region::RightEyeSocket,
        Region::LeftEyeball,
        Region::RightEyeball,
        Region::LeftEar,
        Region::RightEar,
        Region::Neck,
        Region::Boundary,
        Region::Hair,
        Region::Remainder,
        Region::Nose,
        Region::Skin,
    ];

    /// Position of the region in [`Region::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// The region at a table index, if any.
    pub fn from_index(index: usize) -> Option<Region> {
        Region::ALL.get(index).copied()
    }

    /// The snake_case name used in files, JSON and the editor.
    pub fn name(self) -> &'static str {
        match self {
            Region::TeethUpper => "teeth_upper",
            Region::TeethLower => "teeth_lower",
            Region::Lips => "lips",
            Region::LipsInside => "lips_inside",
            Region::LeftEyeRegion => "left_eye_region",
            Region::RightEyeRegion => "right_eye_region",
            Region::LeftEyeSocket => "left_eye_socket",
            Region::RightEyeSocket => "right_eye_socket",
            Region::LeftEyeball => "left_eyeball",
            Region::RightEyeball => "right_eyeball",
            Region::LeftEar => "left_ear",
            Region::RightEar => "right_ear",
            Region::Neck => "neck",
            Region::Boundary => "boundary",
            Region::Hair => "hair",
            Region::Remainder => "remainder",
            Region::Nose => "nose",
            Region::Skin => "skin",
        }
    }

    /// Parses a region name as written by [`Region::name`].
    pub fn from_name(name: &str) -> Option<Region> {
        Region::ALL.into_iter().find(|r| r.name() == name)
    }

    /// The editing group this region belongs to.
    pub fn group(self) -> Group {
        match self {
            Region::TeethUpper | Region::TeethLower | Region::Lips | Region::LipsInside => {
                Group::Mouth
            }
            Region::LeftEyeRegion
            | Region::RightEyeRegion
            | Region::LeftEyeSocket
            | Region::RightEyeSocket
            | Region::LeftEyeball
            | Region::RightEyeball => Group::Eyes,
            Region::LeftEar | Region::RightEar => Group::Ears,
            Region::Neck | Region::Boundary => Group::Neck,
            Region::Hair | Region::Remainder => Group::Hair,
            Region::Nose => Group::Nose,
            Region::Skin => Group::Face,
        }
    }

    /// The main-surface regions a disjoint part is tied to by anchor edges when
    /// blending shapes (thesis 4.1.2), or `None` for regions of the main surface.
    pub fn anchor_regions(self) -> Option<[Region; 2]> {
        match self {
            Region::LeftEyeball => Some([Region::LeftEyeSocket, Region::LeftEyeRegion]),
            Region::RightEyeball => Some([Region::RightEyeSocket, Region::RightEyeRegion]),
            Region::TeethUpper | Region::TeethLower => Some([Region::Lips, Region::LipsInside]),
            _ => None,
        }
    }
}

impl Group {
    /// Number of groups.
    pub const COUNT: usize = 7;

    /// All groups in table order.
    pub const ALL: [Group; Group::COUNT] = [
        Group::Mouth,
        Group::Eyes,
        Group::Ears,
        Group::Neck,
        Group::Hair,
        Group::Nose,
        Group::Face,
    ];

    /// Position of the group in [`Group::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// The snake_case name used in files, JSON and the editor.
    pub fn name(self) -> &'static str {
        match self {
            Group::Mouth => "mouth",
            Group::Eyes => "eyes",
            Group::Ears => "ears",
            Group::Neck => "neck",
            Group::Hair => "hair",
            Group::Nose => "nose",
            Group::Face => "face",
        }
    }

    /// Parses a group name as written by [`Group::name`].
    pub fn from_name(name: &str) -> Option<Group> {
        Group::ALL.into_iter().find(|g| g.name() == name)
    }

    /// The regions of this group, in table order.
    pub fn regions(self) -> impl Iterator<Item = Region> {
        Region::ALL.into_iter().filter(move |r| r.group() == self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_match_the_thesis_partition() {
        let names = |g: Group| g.regions().map(Region::name).collect::<Vec<_>>();
        assert_eq!(
            names(Group::Mouth),
            ["teeth_upper", "teeth_lower", "lips", "lips_inside"]
        );
        assert_eq!(names(Group::Eyes).len(), 6);
        assert_eq!(names(Group::Ears), ["left_ear", "right_ear"]);
        assert_eq!(names(Group::Neck), ["neck", "boundary"]);
        assert_eq!(names(Group::Hair), ["hair", "remainder"]);
        assert_eq!(names(Group::Nose), ["nose"]);
        assert_eq!(names(Group::Face), ["skin"]);
        let total: usize = Group::ALL.iter().map(|g| g.regions().count()).sum();
        assert_eq!(total, Region::COUNT);
    }

    #[test]
    fn names_round_trip() {
        for r in Region::ALL {
            assert_eq!(Region::from_name(r.name()), Some(r));
            assert_eq!(Region::from_index(r.index()), Some(r));
        }
        for g in Group::ALL {
            assert_eq!(Group::from_name(g.name()), Some(g));
        }
        assert_eq!(Region::from_name("forehead"), None);
    }
}
