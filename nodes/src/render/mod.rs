//! Rendering a BTF-mapped mesh, with mesostructure silhouettes from an MDF (thesis ch. 4).

pub mod environment;
pub mod gpu_render;
pub mod material;
pub mod reference;
pub mod relief;
pub mod relief_gpu;
pub mod relief_scene;
pub mod render_mesh;
pub mod rings;
pub mod shade;
pub mod surface;
pub mod volume;
