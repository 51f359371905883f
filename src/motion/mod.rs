//! Motion data: BVH in and out, retargeting real motion capture onto the body model.

pub mod bvh;
pub mod export;
pub mod files;
pub mod json;
pub mod retarget;
