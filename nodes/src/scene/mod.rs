//! What a view sees of a scene, before any model renders it (`scene.footprint`).

pub mod footprint;
