//! Export to the renderers users already have: `export.mitsuba` writes a Mitsuba 3 scene (XML)
//! and `export.pbrt` a pbrt-v4 scene, each the scene `render.reference` renders from the same
//! parameters (mesh, camera, light, reflectance or medium, samples) with the mesh as PLY and the
//! albedo map as EXR beside it. `scene.rs` reads the parameters and inputs once for both
//! (checks, units, the two-lobe mix, the files); each writer holds its renderer's names.

pub mod mitsuba;
pub mod pbrt;
pub mod scene;
