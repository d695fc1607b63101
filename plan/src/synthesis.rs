//! The synthesis stage: a `synthesis.texture` the renderer reads, stopped a level or two early.

use crate::*;
use mesoflow_graph::GraphFile;
use serde_json::{json, Value};
use std::collections::BTreeSet;

/// Each `synthesis.texture` whose image the render reads: stopped 2 or 1 pyramid levels before
/// its finest (its output 4 or 2 times smaller per side, the full run's own coarser result) —
/// the earliest that still gives a texel per pixel where the view sees the tile finest (no more
/// output texels than the view shows) and that the measured model predicts within a tenth of the
/// budget; with a budget of 1 or more, the earliest whose patches fit. In a copy the render
/// reads, never in place (other consumers may want the full texture).
pub(crate) fn decide_synthesis(cx: &Stage, out: &mut GraphFile, b: f64) -> Vec<Decision> {
    use mesoflow_nodes::synthesis::{optimize, texture};
    let Stage {
        model,
        file,
        render,
        scene,
        full,
        cheapest,
        ..
    } = *cx;
    let mut decisions = Vec::new();
    let Some(r) = file.node(render) else {
        return decisions;
    };
    if full {
        return decisions;
    }
    let sources: BTreeSet<String> = r
        .inputs
        .values()
        .filter_map(|f| f.split_once('.'))
        .filter(|(id, _)| file.node(id).is_some_and(|n| n.kind == "synthesis.texture"))
        .map(|(id, _)| id.to_string())
        .collect();
    for id in sources {
        let Some(node) = file.node(&id) else { continue };
        let Ok(p) = serde_json::from_value::<texture::Params>(Value::Object(node.params.clone()))
        else {
            continue;
        };
        let view = |port: &str| node.inputs.get(port).and_then(|s| scene.textures.get(s));
        let Some(ex) = view("exemplar") else {
            decisions.push(Decision {
                stage: "synthesis",
                choice: json!({ "node": id, "stop_level": p.stop_level }),
                reason: format!("`{id}`'s exemplar is not measured: kept"),
                predicted_error: Some(0.0),
                predicted_cost: None,
            });
            continue;
        };
        let default = view("target_guide").map_or((ex.width, ex.height), |g| (g.width, g.height));
        let w = if p.width == 0 {
            default.0
        } else {
            p.width as usize
        };
        let h = if p.height == 0 {
            default.1
        } else {
            p.height as usize
        };
        let tpp = ex.at(w, h);
        let mut sizes: Vec<usize> = p.patch_sizes.iter().map(|&z| z as usize).collect();
        sizes.sort_unstable_by(|a, b| b.cmp(a));
        sizes.dedup();
        let fits = |k: u32| {
            let s = optimize::Settings {
                width: w,
                height: h,
                levels: p.levels as usize,
                stop: k as usize,
                sizes: sizes.clone(),
                iterations: 1,
                exponent: p.exponent,
                periodic: p.periodic,
                rounds: 1,
                seed: 0,
            };
            k < p.levels
                && optimize::plan((ex.width, ex.height), (w, h), &s)
                    .last()
                    .is_some_and(|(l, _)| *l == k as usize)
        };
        let limit = 0.1 * b;
        let pick: Option<(u32, Option<f64>, Option<f64>)> = if cheapest {
            (p.stop_level + 1..p.levels)
                .rev()
                .find(|&k| fits(k))
                .map(|k| {
                    let c = model.synthesis.iter().find(|c| c.stop_level == k);
                    (
                        k,
                        c.and_then(|c| c.flip.at(tpp)).map(|e| e.0),
                        c.and_then(|c| c.time),
                    )
                })
        } else {
            model.synthesis.iter().find_map(|c| {
                let k = c.stop_level;
                if k <= p.stop_level || (1u64 << k) as f64 > tpp || !fits(k) {
                    return None;
                }
                let (e, inside) = c.flip.at(tpp)?;
                (inside && e <= limit).then_some((k, Some(e), c.time))
            })
        };
        let Some((k, e, time)) = pick else {
            decisions.push(Decision {
                stage: "synthesis",
                choice: json!({ "node": id, "stop_level": p.stop_level }),
                reason: format!(
                    "`{id}`'s {w} × {h} output has {tpp:.2} texels per pixel where the tile is seen finest: kept (stopping a level early must keep a texel per pixel, fit its patches and be predicted within a tenth of {b:.3})"
                ),
                predicted_error: Some(0.0),
                predicted_cost: None,
            });
            continue;
        };
        let copy = format!("{PREFIX}{id}");
        let mut params = node.params.clone();
        params.insert("stop_level".into(), json!(k));
        upsert(out, &copy, "synthesis.texture", params, node.inputs.clone());
        if let Some(rn) = out.node_mut(render) {
            for from in rn.inputs.values_mut() {
                if let Some((src, port)) = from.split_once('.') {
                    if src == id {
                        *from = format!("{copy}.{port}");
                    }
                }
            }
        }
        let (ow, oh) = (w >> k, h >> k);
        let mut cost = json!({ "texels_vs_full": (ow * oh) as f64 / (w * h) as f64 });
        if let Some(t) = time {
            cost["synthesis_time_vs_full"] = json!(t);
        }
        let why = if cheapest {
            "a budget of 1 or more: the earliest stop whose patches fit".to_string()
        } else {
            format!(
                "predicted at FLIP {:.4}, within a tenth of {b:.3}",
                e.unwrap_or(f64::NAN)
            )
        };
        decisions.push(Decision {
            stage: "synthesis",
            choice: json!({ "node": id, "stop_level": k, "size": [ow, oh] }),
            reason: format!(
                "`{id}`'s {w} × {h} output has {tpp:.2} texels per pixel where the tile is seen finest: stopped {k} level(s) early ({ow} × {oh}), {why}"
            ),
            predicted_error: e,
            predicted_cost: Some(cost),
        });
    }
    decisions
}
