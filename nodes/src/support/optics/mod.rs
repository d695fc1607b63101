//! Optics shared by the renderers and the scattering models: Fresnel's equations and their
//! moments, Chandrasekhar's H function, the Henyey–Greenstein phase function, and the rough
//! dielectric boundary. `render/` and `sss/` both use these and import nothing from each other
//! for them.

pub mod chandrasekhar;
pub mod dielectric;
pub mod fresnel;
pub mod phase;
