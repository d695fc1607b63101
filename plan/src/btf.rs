//! The BTF stage: raw, or a PCA basis of some rank at some level of detail.

use crate::*;
use mesoflow_graph::GraphFile;
use serde_json::{json, Map};

/// The BTF's model: raw, or a PCA basis of `rank` (luma) and `chroma_rank` at `level`.
#[derive(Clone, Debug, PartialEq)]
pub struct BtfModel {
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
                raw: true,
                level: 0.0,
                rank: 0,
                chroma_rank: 0,
            },
        )
    };
    if full {
        return raw(
            "budget 0: the full model is the raw BTF at full resolution".into(),
            0.0,
        );
    }
    // Memory of a basis: per block of rank k, k maps at the level's resolution, a mean, and
    // k basis vectors over the pairs.
    let texels = scene.tile_texels.unwrap_or(64.0).powi(2);
    let pairs = scene.btf_pairs.unwrap_or(0.0);
    let floats = |r: u32, l: f64| {
        let chroma = (r / 4).max(1) as f64;
        let at = (texels / 4f64.powf(l)).max(1.0);
        (r as f64 + 2.0 * chroma) * (at + pairs) + 3.0 * at
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
        return raw("texels per pixel unknown: the raw BTF".into(), 0.0);
    };
    let best = model
        .btf
        .iter()
        .filter(|o| o.level as f64 <= coarsest)
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
        None => raw(
            format!("{t:.2} texels per pixel: no PCA rank and level is predicted within this stage's {share:.3}; the raw BTF"),
            0.0,
        ),
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
