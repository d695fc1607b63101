//! The MDF stage: left out, or tabulated coarser than its height field.

use crate::*;
use mesoflow_graph::GraphFile;
use serde_json::{json, Value};

/// The MDF: left out when the shell is under half a pixel, or when leaving it out is predicted
/// within the stage's share; `None` when the render has no MDF connected.
pub(crate) fn decide_mdf(cx: &Stage, out: &mut GraphFile, share: f64) -> Option<Decision> {
    let Stage {
        model,
        file,
        render,
        scene,
        full,
        cheapest,
        why_cheapest,
        ..
    } = *cx;
    if !file.node(render)?.inputs.contains_key("mdf") {
        return None;
    }

    let predicted_off =
        scene
            .shell_pixels
            .zip(scene.silhouette_fraction)
            .and_then(|(px, contour)| {
                model.mdf_off_per_contour.at(px).map(|(e, inside)| {
                    let band = calibration::band_fraction(contour, px);
                    ((e * band).min(1.0), inside)
                })
            });
    let (keep, reason, predicted) = if full {
        (
            true,
            "budget 0: the full model keeps the MDF".to_string(),
            Some(0.0),
        )
    } else if cheapest {
        (false, why_cheapest.to_string(), predicted_off.map(|p| p.0))
    } else {
        match (scene.shell_pixels, predicted_off) {
            (Some(px), _) if px < 0.5 => (
                false,
                format!("the shell projects to {px:.2} px, under half a pixel: no silhouette to see"),
                predicted_off.map(|p| p.0),
            ),
            (Some(px), Some((e, true))) if e <= share => (
                false,
                format!("the shell projects to {px:.2} px; leaving the MDF out is predicted to cost FLIP {e:.3}, within this stage's {share:.3}"),
                Some(e),
            ),
            (Some(px), Some((e, true))) => (
                true,
                format!("the shell projects to {px:.2} px; leaving the MDF out is predicted to cost FLIP {e:.3}, over this stage's {share:.3}"),
                Some(0.0),
            ),
            (Some(px), Some((_, false))) => (
                true,
                format!("the shell projects to {px:.2} px, beyond the calibrated range: the MDF is kept"),
                Some(0.0),
            ),
            _ => (true, "the shell's projection is unknown: kept".to_string(), None),
        }
    };
    if !keep {
        if let Some(n) = out.node_mut(render) {
            n.inputs.remove("mdf");
            n.params.insert("use_mdf".into(), json!(false));
        }
    }
    let time = scene
        .shell_pixels
        .and_then(|px| model.mdf_off_time.at(px))
        .filter(|_| !keep)
        .map(|(t, _)| json!({ "render_time_vs_full": t }));
    Some(Decision {
        stage: "mdf",
        choice: json!({ "use_mdf": keep }),
        reason,
        predicted_error: predicted,
        predicted_cost: time,
    })
}

/// The MDF's table, where kept: tabulated 8, 4 or 2 times coarser than its height field — the
/// coarsest that still has a texel per pixel where the view sees the tile finest (the resolution
/// the footprint needs) and that the measured model predicts within the stage's share: the MDF
/// was kept because leaving it out costs more than the share, and a coarser table is the
/// stage's next cheaper model. `None` where the render has no MDF, the budget asks for the full
/// model, or the table is not tabulated from a height field.
pub(crate) fn decide_mdf_resolution(
    cx: &Stage,
    out: &mut GraphFile,
    share: f64,
) -> Option<Decision> {
    let Stage {
        model,
        file,
        render,
        scene,
        full,
        ..
    } = *cx;
    if full {
        return None;
    }
    let from = out.node(render)?.inputs.get("mdf")?.clone();
    let (id, port) = from.split_once('.')?;
    let node = file.node(id).filter(|n| n.kind == "mdf.tabulate")?;
    let height = node.inputs.get("height")?;
    let Some(tex) = scene.textures.get(height) else {
        return Some(Decision {
            stage: "mdf_resolution",
            choice: json!({ "resolution": node.params.get("resolution") }),
            reason: "the height field's texels per pixel are unknown: the table is kept".into(),
            predicted_error: Some(0.0),
            predicted_cost: None,
        });
    };
    let width = node
        .params
        .get("resolution")
        .and_then(Value::as_u64)
        .map_or(tex.width, |w| w as usize);
    let height_texels = (width as f64 * tex.height as f64 / tex.width as f64).round() as usize;
    let tpp = tex.at(width, height_texels);
    let band = scene
        .silhouette_fraction
        .zip(scene.shell_pixels)
        .map(|(s, px)| calibration::band_fraction(s, px));
    let limit = share;
    let mut why_not = Vec::new();
    let pick = model.mdf_resolution.iter().find_map(|c| {
        let coarse = width / c.factor as usize;
        if coarse < 8 || (c.factor as f64) > tpp {
            return None;
        }
        let (e, inside) = c.flip_per_contour.at(tpp)?;
        let e = (e * band?).min(1.0);
        if inside && e <= limit {
            Some((c, coarse, e))
        } else {
            why_not.push(format!(
                "{}× coarser is predicted at FLIP {e:.4}{}",
                c.factor,
                range_note(inside)
            ));
            None
        }
    });
    let Some((c, coarse, e)) = pick else {
        let detail = if why_not.is_empty() {
            String::new()
        } else {
            format!("; {}", why_not.join(", "))
        };
        return Some(Decision {
            stage: "mdf_resolution",
            choice: json!({ "resolution": width }),
            reason: format!(
                "the table has {tpp:.2} texels per pixel where the tile is seen finest: kept at {width} texels (a coarser one must keep a texel per pixel and stay within {share:.3}{detail})"
            ),
            predicted_error: Some(0.0),
            predicted_cost: None,
        });
    };
    let mut params = node.params.clone();
    params.insert("resolution".into(), json!(coarse));
    let copy = format!("{PREFIX}mdf");
    upsert(out, &copy, "mdf.tabulate", params, node.inputs.clone());
    out.node_mut(render)?
        .inputs
        .insert("mdf".into(), format!("{copy}.{port}"));
    let mut cost = json!({ "table_entries_vs_full": 1.0 / (c.factor * c.factor) as f64 });
    if let Some(t) = c.time {
        cost["tabulation_time_vs_full"] = json!(t);
    }
    Some(Decision {
        stage: "mdf_resolution",
        choice: json!({ "resolution": coarse }),
        reason: format!(
            "the table has {tpp:.2} texels per pixel where the tile is seen finest: tabulated {}× coarser ({coarse} texels, not {width}), predicted at FLIP {e:.4}, within this stage's {share:.3}",
            c.factor
        ),
        predicted_error: Some(e),
        predicted_cost: Some(cost),
    })
}
