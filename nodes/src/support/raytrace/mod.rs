//! What every renderer traces with: the camera, the light (directional, point or environment), the mesh's visibility layers (depth
//! peeling on the CPU), rays against a mesh (`tracer`), shadow maps and the pixel footprint's
//! metrics. `render/` and `sss/` both build on these and import nothing from each other.

pub mod bvh_store;
pub mod camera;
pub mod environment;
pub mod footprint;
pub mod layers;
pub mod light;
pub mod shadow;
pub mod tracer;
pub mod view;
