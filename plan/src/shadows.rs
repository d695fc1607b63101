//! The shadow map's resolution.

use crate::*;
use mesoflow_graph::GraphFile;
use mesoflow_nodes::support::raytrace::footprint::shadow_resolution;
use serde_json::{json, Value};

/// Shadow maps: the renderer's resolution lowered to what the view shows, at the sparsest
/// calibrated density the measured model predicts within a tenth of the budget (the change is
/// meant to be invisible).
pub(crate) fn decide_shadows(cx: &Stage, out: &mut GraphFile, b: f64) -> Option<Decision> {
    let Stage {
        model,
        file,
        render,
        kind,
        scene,
        full,
        cheapest,
        ..
    } = *cx;
    let node = file.node(render)?;
    let defaults = match kind {
        RenderKind::Mesh => (false, 1024),
        RenderKind::Sss | RenderKind::Qh => (true, 1024),
    };
    let on = node
        .params
        .get("shadows")
        .and_then(Value::as_bool)
        .unwrap_or(defaults.0);
    if !on || full {
        return None;
    }
    let current = node
        .params
        .get("shadow_resolution")
        .and_then(Value::as_u64)
        .map_or(defaults.1, |v| v as u32);
    let px = scene.object_pixels?;
    let curves = match kind {
        RenderKind::Sss => &model.shadows_sss,
        RenderKind::Mesh | RenderKind::Qh => &model.shadows_mesh,
    };
    // The sparsest calibrated density predicted invisible (within a tenth of the budget); the
    // sparsest of all when the budget asks for the cheapest.
    let (size, density, e, inside, time) = curves.iter().find_map(|c| {
        let size = shadow_resolution(px, c.texels_per_pixel, current);
        let (e, inside) = c.flip.at(px)?;
        let ok = size < current && (cheapest || (inside && e <= 0.1 * b));
        ok.then(|| (size, c.texels_per_pixel, e, inside, c.time.at(px)))
    })?;
    if let Some(n) = out.node_mut(render) {
        n.params.insert("shadow_resolution".into(), json!(size));
    }
    Some(Decision {
        stage: "shadows",
        choice: json!({ "shadow_resolution": size }),
        reason: format!(
            "the object spans {px:.0} px: a {size}² shadow map (not {current}²), {density} texels per pixel, is predicted at FLIP {e:.4}{}",
            range_note(inside)
        ),
        predicted_error: Some(e),
        predicted_cost: time.map(|(t, _)| json!({ "render_time_vs_full": t })),
    })
}
