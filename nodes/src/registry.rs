//! Every node kind and value type mesoflow ships. Adding a kind: write its file, add one line here.

use mesoflow_runtime::Registry;

pub fn builtin() -> Registry {
    let mut r = Registry::new();
    crate::types::register(&mut r);
    r.register(crate::btf::capture::Capture);
    r.register(crate::btf::compare::Compare);
    r.register(crate::btf::pca::Pca);
    r.register(crate::btf::lod::Lod);
    r.register(crate::btf::read_ubo2003::ReadUbo2003);
    r.register(crate::btf::reconstruct::Reconstruct);
    r.register(crate::btf::write_ubo2003::WriteUbo2003);
    r.register(crate::btf::read_ubo2014::ReadUbo2014);
    r.register(crate::btf::write_ubo2014::WriteUbo2014);
    r.register(crate::heightfield::procedural::Procedural);
    r.register(crate::heightfield::read::Read);
    r.register(crate::heightfield::normals::Normals);
    r.register(crate::heightfield::from_normals::FromNormals);
    r.register(crate::heightfield::normal_noise::NormalNoise);
    r.register(crate::heightfield::edit::Edit);
    r.register(crate::brdf::edit::Edit);
    r.register(crate::material::transfer::Transfer);
    r.register(crate::image::compare::Compare);
    r.register(crate::image::flip::Flip);
    r.register(crate::scene::footprint::SceneFootprint);
    r.register(crate::image::row::Row);
    r.register(crate::image::difference::Difference);
    r.register(crate::image::blur::Blur);
    r.register(crate::image::ramp::Ramp);
    r.register(crate::image::colorize::Colorize);
    r.register(crate::image::read::ImageRead);
    r.register(crate::image::array::ImageArray);
    r.register(crate::heightfield::array::HeightFieldArray);
    r.register(crate::btf::array::BtfArray);
    r.register(crate::points::array::PointsArray);
    r.register(crate::mdf::tabulate::Tabulate);
    r.register(crate::mesh::primitive::Primitive);
    r.register(crate::mesh::displace::Displace);
    r.register(crate::mesh::write::MeshWrite);
    r.register(crate::mesh::read::Read);
    r.register(crate::render::render_mesh::RenderMesh);
    r.register(crate::render::reference::Reference);
    r.register(crate::export::mitsuba::ExportMitsuba);
    r.register(crate::export::pbrt::ExportPbrt);
    r.register(crate::render::relief::RenderRelief);
    r.register(crate::image::write::ImageWrite);
    r.register(crate::npy::write::NpyWrite);
    r.register(crate::sss::material::Material);
    r.register(crate::sss::profile::Profile);
    r.register(crate::sss::compare::Compare);
    r.register(crate::sss::render::Render);
    r.register(crate::sss::render::lighting::Lighting);
    r.register(crate::qh::fit_dipole::FitDipole);
    r.register(crate::qh::render::QhRender);
    r.register(crate::points::read::PointsRead);
    r.register(crate::points::synthetic::PointsSynthetic);
    r.register(crate::manifold::knn::Knn);
    r.register(crate::manifold::isomap::Isomap);
    r.register(crate::manifold::degree::Degree);
    r.register(crate::manifold::evolve::Evolve);
    r.register(crate::manifold::transfer::Transfer);
    r.register(crate::weathering::sample::WeatheringSample);
    r.register(crate::brdf::fit_ward::FitWard);
    r.register(crate::synthesis::texture::Texture);
    r.register(crate::scalar::Constant);
    r.register(crate::scalar::Affine);
    r.register(crate::debug::Sleep);
    r
}

#[cfg(test)]
mod tests {
    use mesoflow_graph::params::check_params;
    use serde_json::{json, Map, Value};

    /// Values that break parameter structs in ways a JSON Schema may not say.
    fn hostile() -> Vec<Value> {
        vec![
            json!(4294967296u64),
            json!(-1),
            json!(-0.0),
            json!(1.5),
            json!(18446744073709551615u64),
            json!(1e308),
            json!(-1e308),
            json!({}),
            json!([]),
            json!(""),
            json!(null),
            json!(true),
            json!([[1e308, -1e308]]),
            json!({"thetas": [], "phis": []}),
        ]
    }

    /// Ranges are stated once, in each kind's schema, which validation applies before the
    /// kind's `check()` (which holds only what a schema cannot say). Every range below was once
    /// restated by hand in a `check()`; the schema alone refuses each value now, naming the
    /// parameter.
    #[test]
    fn the_schema_alone_holds_each_range() {
        let r = super::builtin();
        let cases: &[(&str, &str, Value)] = &[
            ("image.blur", "sigma", json!(1000.5)),
            ("image.ramp", "width", json!(0)),
            ("image.ramp", "height", json!(16385)),
            ("heightfield.normal_noise", "sigma_deg", json!(46.0)),
            ("heightfield.normal_noise", "outliers", json!(1.5)),
            ("heightfield.normal_noise", "outlier_deg", json!(-1.0)),
            ("image.difference", "scale", json!(0.0)),
            ("points.synthetic", "noise", json!(-0.1)),
            ("sss.profile", "photons", json!(999)),
            ("mesh.displace", "shell", json!(-1.0)),
            ("mesh.displace", "depth", json!(2e6)),
            ("mesh.displace", "density", json!(0.2)),
            ("mesh.displace", "max_triangles", json!(0)),
            ("btf.read_ubo2014", "stride", json!(0)),
            ("btf.read_ubo2014", "downsample", json!(65)),
            ("btf.capture", "samples", json!(17)),
            ("scene.footprint", "shell", json!(-1.0)),
            ("qh.fit_dipole", "eta", json!(0.0)),
            ("qh.fit_dipole", "photons", json!(999)),
            ("image.flip", "ppd", json!(0.1)),
            (
                "image.flip",
                "viewer",
                json!({"distance_m": 0.0, "width_m": 0.5}),
            ),
            ("image.write", "scale", json!(65)),
            ("image.write", "exposure", json!(-1.0)),
            ("render.reference", "specular", json!(1.5)),
            ("render.reference", "roughness", json!(0.0)),
            ("render.reference", "boundary_roughness", json!(0.005)),
            ("render.reference", "samples", json!(0)),
            ("render.mesh", "shell", json!(-1.0)),
            ("render.relief", "shell", json!(2e9)),
            ("render.relief", "linear_steps", json!(0)),
            ("render.relief", "binary_steps", json!(33)),
            ("render.relief", "frames", json!(1001)),
            ("manifold.evolve", "step", json!(-1.0)),
            ("weathering.sample", "radius", json!(0.0)),
            ("weathering.sample", "roughness", json!(-1.0)),
            ("weathering.sample", "noise", json!(-1.0)),
            ("weathering.sample", "bumps", json!(-1.0)),
            ("synthesis.texture", "levels", json!(0)),
            ("synthesis.texture", "iterations", json!(0)),
            ("synthesis.texture", "search_rounds", json!(0)),
            ("synthesis.texture", "guide_weight", json!(-1.0)),
            ("heightfield.edit", "amount", json!(101.0)),
            ("brdf.edit", "hue_deg", json!(400.0)),
            ("brdf.edit", "saturation", json!(-1.0)),
            ("brdf.edit", "value", json!(101.0)),
            ("brdf.edit", "specular_scale", json!(1001.0)),
            ("brdf.edit", "roughness_scale", json!(0.0)),
            ("brdf.fit_ward", "min_roughness", json!(0.001)),
            // The exports flatten render.reference's parameters: their ranges come with them.
            ("export.mitsuba", "samples", json!(0)),
            ("export.mitsuba", "specular", json!(1.5)),
            ("export.pbrt", "boundary_roughness", json!(0.005)),
            ("export.pbrt", "translucency", json!("bssrdf")),
        ];
        for (kind, param, value) in cases {
            let sig = r
                .signatures()
                .find(|s| s.kind == *kind)
                .unwrap_or_else(|| panic!("no kind {kind}"));
            let params: Map<String, Value> =
                [(param.to_string(), value.clone())].into_iter().collect();
            let errors = check_params("n", kind, &sig.params, &params);
            assert!(
                errors.iter().any(|e| e.to_string().contains(param)),
                "{kind}.{param} = {value} passed the schema: {errors:?}"
            );
        }
    }

    /// The view parameters are declared once (`raytrace::view`): every kind that has one has
    /// the same schema for it (type, range, documentation), its default aside. A kind that
    /// declared `tiling` or `mm_per_unit` by hand again, with its own words or range, fails here.
    #[test]
    fn every_kind_with_a_view_parameter_shares_its_one_definition() {
        let r = super::builtin();
        let mut first: std::collections::BTreeMap<&str, (String, Value)> = Default::default();
        let mut seen = 0;
        for sig in r.signatures() {
            let Some(props) = sig.params["properties"].as_object() else {
                continue;
            };
            // Kinds that see a scene: a `light` or `background` elsewhere (a manifold's light
            // angles, `image.row`'s gap colour) is another parameter of the same name.
            if !props.contains_key("camera") && !props.contains_key("tiling") {
                continue;
            }
            for field in crate::support::raytrace::view::ALL {
                let Some(schema) = props.get(field) else {
                    continue;
                };
                let mut schema = schema.clone();
                schema.as_object_mut().unwrap().remove("default");
                seen += 1;
                match first.get(field) {
                    None => {
                        first.insert(field, (sig.kind.clone(), schema));
                    }
                    Some((kind, other)) => assert_eq!(
                        &schema, other,
                        "`{field}` of {} differs from {kind}'s",
                        sig.kind
                    ),
                }
            }
        }
        // render.mesh, render.relief, render.reference, scene.footprint, sss.render, qh.render.
        assert!(seen >= 30, "only {seen} view parameters found");
    }

    #[test]
    fn the_schema_accepts_nothing_the_parameters_refuse() {
        // `validate` runs both the schema and the typed check, so a user never meets a value
        // that validates and then fails to load. This holds the schema itself (what editors and
        // the studio read) to the same standard: every value it accepts, the struct accepts.
        let r = super::builtin();
        let mut disagree = Vec::new();
        let mut tried = 0;
        for sig in r.signatures() {
            let node = r.node(&sig.kind).unwrap();
            let props = sig.params["properties"]
                .as_object()
                .cloned()
                .unwrap_or_default();
            let required = sig.required_params();
            let mut base = Map::new();
            for r in &required {
                base.insert(r.to_string(), json!("x.png"));
            }
            // A kind whose defaults alone are refused (one of several parameters must be given,
            // as in `sss.material`) fails with that rule whatever one value is: not this value.
            let base_error = node.prepare(&base).err().map(|e| e.to_string());
            for name in props.keys() {
                for v in hostile() {
                    let mut params = base.clone();
                    params.insert(name.clone(), v.clone());
                    let schema_ok = check_params("n", &sig.kind, &sig.params, &params).is_empty();
                    let error = node.prepare(&params).err().map(|e| e.to_string());
                    tried += 1;
                    if schema_ok && error.is_some() && error != base_error {
                        disagree.push(format!("{}.{name} = {v}: {error:?}", sig.kind));
                    }
                }
            }
        }
        println!("{tried} (kind, parameter, value) cases");
        assert!(
            disagree.is_empty(),
            "{} disagreements:\n{}",
            disagree.len(),
            disagree.join("\n")
        );
    }
}

#[cfg(test)]
mod docs {
    use serde_json::Value;

    /// Every property of every parameter object (nested ones included) has a description.
    fn undocumented(root: &Value, s: &Value, path: &str, out: &mut Vec<String>, depth: usize) {
        if depth > 8 {
            return;
        }
        let resolve = |v: &Value| -> Value {
            match v.get("$ref").and_then(Value::as_str) {
                Some(r) => {
                    let name = r.rsplit('/').next().unwrap_or_default();
                    let mut d = root["$defs"][name].clone();
                    if let (Value::Object(d), Value::Object(o)) = (&mut d, v) {
                        for (k, x) in o.iter().filter(|(k, _)| k.as_str() != "$ref") {
                            d.insert(k.clone(), x.clone());
                        }
                    }
                    d
                }
                None => v.clone(),
            }
        };
        let s = resolve(s);
        if let Some(props) = s.get("properties").and_then(Value::as_object) {
            for (k, v) in props {
                let v = resolve(v);
                if v.get("description").is_none() {
                    out.push(format!("{path}{k}"));
                }
                undocumented(root, &v, &format!("{path}{k}."), out, depth + 1);
            }
        }
        for key in ["anyOf", "oneOf"] {
            for b in s.get(key).and_then(Value::as_array).into_iter().flatten() {
                undocumented(root, b, path, out, depth + 1);
            }
        }
    }

    #[test]
    fn every_parameter_field_is_documented() {
        let r = super::builtin();
        let mut missing = Vec::new();
        for sig in r.signatures() {
            let mut out = Vec::new();
            undocumented(&sig.params, &sig.params, "", &mut out, 0);
            missing.extend(out.into_iter().map(|p| format!("{}: {p}", sig.kind)));
        }
        assert!(
            missing.is_empty(),
            "{} undocumented:\n{}",
            missing.len(),
            missing.join("\n")
        );
    }
}
