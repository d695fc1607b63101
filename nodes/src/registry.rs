//! Every node kind and value type mesoflow ships. Adding a kind: write its file, add one line here.

use mesoflow_runtime::Registry;

pub fn registry() -> Registry {
    let mut r = Registry::new();
    crate::types::register(&mut r);
    r.register(crate::btf::capture::Capture);
    r.register(crate::btf::compare::Compare);
    r.register(crate::btf::pca::Pca);
    r.register(crate::btf::lod::Lod);
    r.register(crate::btf::read_ubo2003::ReadUbo2003);
    r.register(crate::btf::reconstruct::Reconstruct);
    r.register(crate::btf::write_ubo2003::WriteUbo2003);
    r.register(crate::heightfield::procedural::Procedural);
    r.register(crate::heightfield::read::Read);
    r.register(crate::heightfield::normals::Normals);
    r.register(crate::image::compare::Compare);
    r.register(crate::image::row::Row);
    r.register(crate::image::blur::Blur);
    r.register(crate::image::ramp::Ramp);
    r.register(crate::io::image_read::ImageRead);
    r.register(crate::mdf::tabulate::Tabulate);
    r.register(crate::mesh::primitive::Primitive);
    r.register(crate::mesh::read::Read);
    r.register(crate::render::render_mesh::RenderMesh);
    r.register(crate::io::image_write::ImageWrite);
    r.register(crate::io::npy_write::NpyWrite);
    r.register(crate::sss::material::Material);
    r.register(crate::sss::profile::Profile);
    r.register(crate::sss::compare::Compare);
    r.register(crate::sss::render::Render);
    r.register(crate::qh::fit_dipole::FitDipole);
    r.register(crate::qh::render::QhRender);
    r.register(crate::manifold::points_read::PointsRead);
    r.register(crate::manifold::points_synthetic::PointsSynthetic);
    r.register(crate::manifold::knn::Knn);
    r.register(crate::manifold::isomap::Isomap);
    r.register(crate::manifold::degree::Degree);
    r.register(crate::manifold::evolve::Evolve);
    r.register(crate::manifold::transfer::Transfer);
    r.register(crate::weathering::sample::WeatheringSample);
    r.register(crate::brdf::fit_ward::FitWard);
    r.register(crate::synthesis::texture::Texture);
    r.register(crate::util::scalar::Constant);
    r.register(crate::util::scalar::Affine);
    r.register(crate::util::sleep::Sleep);
    r
}
