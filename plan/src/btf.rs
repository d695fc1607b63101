//! The BTF stage: raw, or a PCA basis of some rank at some level of detail.

use crate::*;
use mesoflow_graph::GraphFile;
use serde_json::{json, Map};

/// The BTF's model: raw, or a PCA basis of `rank` (luma) and `chroma_rank` at `level`.
#[derive(Clone, Debug, PartialEq)]
pub struct BtfModel {
    /// The graph's own model, left as it is.
    pub given: bool,
    pub raw: bool,
    pub level: f64,
    pub rank: u32,
    pub chroma_rank: u32,
}

/// " (beyond the calibrated range: its nearest end)" where a prediction is extrapolated.
pub(crate) fn range_note(inside: bool) -> &'static str {
    if inside {
        ""
    } else {
        " (beyond the calibrated range: its nearest end)"
    }
}

pub(crate) fn decide_btf(cx: &Stage, share: f64) -> (Decision, BtfModel) {
    let Stage {
        model,
        scene,
        full,
        cheapest,
        why_cheapest,
        ..
    } = *cx;
    let coarsest = scene.tile_texels.map_or(0.0, |t| t.max(1.0).log2().ceil());
    let raw = |reason: String, predicted: f64| {
        (
            Decision {
                stage: "btf",
                choice: json!({ "model": "raw", "level": 0 }),
                reason,
                predicted_error: Some(predicted),
                predicted_cost: Some(match scene.btf_floats {
                    Some(f) => json!({ "floats": f, "render_time_vs_full": 1.0 }),
                    None => json!({ "render_time_vs_full": 1.0 }),
                }),
            },
            BtfModel {
                given: false,
                raw: true,
                level: 0.0,
                rank: 0,
                chroma_rank: 0,
            },
        )
    };
    // Memory of a basis: per block of rank k, k maps at the level's resolution, a mean, and
    // k basis vectors over the pairs.
    let texels = scene.tile_texels.unwrap_or(64.0).powi(2);
    let pairs = scene.btf_pairs.unwrap_or(0.0);
    let basis_floats = |luma: u32, chroma: u32, l: f64| {
        let at = (texels / 4f64.powf(l)).max(1.0);
        (luma as f64 + 2.0 * chroma as f64) * (at + pairs) + 3.0 * at
    };
    let floats = |r: u32, l: f64| basis_floats(r, (r / 4).max(1), l);
    // The graph's own model, which no candidate may exceed, and what a stage with nothing that
    // fits keeps.
    let keep = |reason: String, floats: Option<f64>| {
        (
            Decision {
                stage: "btf",
                choice: json!({ "model": "as given" }),
                reason,
                predicted_error: Some(0.0),
                predicted_cost: Some(match floats {
                    Some(f) => json!({ "floats": f, "render_time_vs_full": 1.0 }),
                    None => json!({ "render_time_vs_full": 1.0 }),
                }),
            },
            BtfModel {
                given: true,
                raw: false,
                level: 0.0,
                rank: 0,
                chroma_rank: 0,
            },
        )
    };
    let limit = match cx.btf_given {
        Some(GivenBtf::Pca {
            rank,
            chroma_rank,
            ycbcr,
            level,
            ..
        }) => {
            let (luma, chroma) = if *ycbcr {
                (*rank, *chroma_rank)
            } else {
                (*rank, *rank)
            };
            Some((*rank, *level, basis_floats(luma, chroma, *level)))
        }
        _ => None,
    };
    let raw_given = matches!(cx.btf_given, Some(GivenBtf::Raw));
    let fallback = |reason: String| {
        if raw_given {
            raw(format!("{reason}; the raw BTF, as the graph gives it"), 0.0)
        } else {
            keep(
                format!("{reason}; the graph's own basis is kept (a plan never gives more model than the graph)"),
                limit.map(|l| l.2),
            )
        }
    };
    if full {
        return fallback("budget 0: the graph's own model".into());
    }
    let within_given = |r: u32, l: f64| {
        limit.is_none_or(|(rank, level, f)| r <= rank && l >= level && floats(r, l) <= f)
    };
    let pca = |r: u32, l: f64, reason: String, predicted: Option<f64>, time: Option<f64>| {
        let chroma = (r / 4).max(1);
        let average = l >= coarsest && coarsest > 0.0;
        (
            Decision {
                stage: "btf",
                choice: json!({ "model": "pca", "color": "ycbcr", "rank": r, "chroma_rank": chroma, "level": l }),
                reason: format!(
                    "{reason}{}",
                    if average {
                        "; at the coarsest level the BTF is its average BRDF"
                    } else {
                        ""
                    }
                ),
                predicted_error: predicted,
                predicted_cost: Some(match time {
                    Some(t) => json!({ "floats": floats(r, l), "render_time_vs_full": t }),
                    None => json!({ "floats": floats(r, l) }),
                }),
            },
            BtfModel {
                given: false,
                raw: false,
                level: l,
                rank: r,
                chroma_rank: chroma,
            },
        )
    };
    let tpp = scene.texels_per_pixel;
    let predict = |o: &calibration::BtfOption| tpp.and_then(|t| o.flip.at(t));
    if cheapest {
        let worst = model
            .btf
            .iter()
            .filter(|o| o.rank == 2 && o.level as f64 >= coarsest.min(5.0))
            .find_map(predict)
            .map(|p| p.0);
        return pca(1, coarsest, why_cheapest.to_string(), worst, None);
    }
    let Some(t) = tpp else {
        return fallback("texels per pixel unknown".into());
    };
    let best = model
        .btf
        .iter()
        .filter(|o| o.level as f64 <= coarsest)
        .filter(|o| within_given(o.rank, o.level as f64))
        .filter_map(|o| predict(o).map(|p| (o, p)))
        .filter(|(_, (e, inside))| *inside && *e <= share)
        .min_by(|a, b| {
            floats(a.0.rank, a.0.level as f64).total_cmp(&floats(b.0.rank, b.0.level as f64))
        });
    match best {
        Some((o, (e, inside))) => pca(
            o.rank,
            o.level as f64,
            format!(
                "{t:.2} texels per pixel: the least memory whose predicted FLIP ({e:.3}{}) fits this stage's {share:.3}",
                range_note(inside)
            ),
            Some(e),
            o.time.at(t).map(|p| p.0),
        ),
        None => fallback(format!(
            "{t:.2} texels per pixel: no PCA rank and level{} is predicted within this stage's {share:.3}",
            if limit.is_some() { " below the graph's" } else { "" }
        )),
    }
}

pub(crate) fn apply_btf(
    out: &mut GraphFile,
    render: &str,
    port: &str,
    chain: &BtfChain,
    m: &BtfModel,
) {
    let set_input = |out: &mut GraphFile, from: String| {
        if let Some(n) = out.node_mut(render) {
            n.inputs.insert(port.into(), from);
        }
    };
    if m.given {
        return;
    }
    if m.raw {
        set_input(out, chain.raw.clone());
        return;
    }
    let pca = format!("{PREFIX}pca");
    let lod = format!("{PREFIX}lod");
    let mut pca_params = Map::new();
    pca_params.insert("color".into(), json!("ycbcr"));
    pca_params.insert("rank".into(), json!(m.rank));
    pca_params.insert("chroma_rank".into(), json!(m.chroma_rank));
    upsert(
        out,
        &pca,
        "btf.pca",
        pca_params,
        [("btf".to_string(), chain.raw.clone())].into(),
    );
    let mut lod_params = Map::new();
    lod_params.insert("level".into(), json!(m.level));
    upsert(
        out,
        &lod,
        "btf.lod",
        lod_params,
        [("basis".to_string(), format!("{pca}.basis"))].into(),
    );
    set_input(out, format!("{lod}.basis"));
}
