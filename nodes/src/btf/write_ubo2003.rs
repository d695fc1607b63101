//! `btf.write_ubo2003`: a `Btf` as a folder of UBO2003-named images, one per direction pair
//! (`{index:05}_tlNNN_plNNN_tvNNN_pvNNN.ext`): PNG 8-bit (sRGB) or 16-bit (linear), for other
//! tools and eyes, or EXR (linear f32, which `btf.read_ubo2003` reads back bit for bit). The running index keeps
//! the BTF's pair order. Angles must be whole degrees, as the names require.

use super::ubo2003;
use crate::support::formats;
use crate::types::Btf;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{
    Artifact, Artifacts, Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port,
};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicU64, Ordering};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// Linear f32, lossless.
    Exr,
    /// `bits` per sample: 8-bit sRGB-encoded, 16-bit linear.
    Png,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Folder, relative to the output folder.
    #[schemars(extend("x-output-path" = true))]
    pub path: String,
    /// File format of the images: `exr` (linear f32) or `png` (`bits` per sample).
    #[serde(default = "exr")]
    pub format: Format,
    /// Bits per PNG sample: 8 or 16.
    #[serde(default = "eight")]
    #[schemars(range(min = 8, max = 16))]
    pub bits: u8,
}

fn exr() -> Format {
    Format::Exr
}
fn eight() -> u8 {
    8
}

pub struct WriteUbo2003;

impl Node for WriteUbo2003 {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "btf.write_ubo2003",
            version: 1,
            doc: "Writes a BTF as UBO2003-named images, one per direction pair: EXR (linear, exact) or PNG (8-bit sRGB, 16-bit linear).",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("btf", Btf::TYPE, "the BTF to write")],
            outputs: vec![Port::output(
                "files",
                Artifacts::TYPE,
                "the images, written under the output folder",
            )],
            disk_cache: false,
        }
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let btf = inputs.get::<Btf>("btf")?;
        if p.format == Format::Png && p.bits != 8 && p.bits != 16 {
            return Err(NodeError::param(
                "bits",
                format!("PNG samples are 8 or 16 bits, got {}", p.bits),
            ));
        }
        let ext = match p.format {
            Format::Exr => "exr",
            Format::Png => "png",
        };
        let names: Vec<String> = btf
            .pairs
            .iter()
            .enumerate()
            .map(|(i, pair)| {
                ubo2003::file_name(i, pair, ext)
                    .map_err(|e| NodeError::input("btf", format!("direction pair {i}: {e}")))
            })
            .collect::<Result<_, _>>()?;
        let done = AtomicU64::new(0);
        let total = names.len() as u64;
        let files = names
            .par_iter()
            .enumerate()
            .map(|(i, name)| {
                ctx.check_cancel()?;
                let img = btf.preview(i);
                let bytes = match p.format {
                    Format::Exr => formats::encode_exr(&img),
                    Format::Png => formats::encode_png(&img, p.bits),
                }
                .map_err(|e| NodeError::Failed(format!("encoding {name}: {e}")))?;
                ctx.progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
                Ok(Artifact {
                    path: format!("{}/{name}", p.path.trim_end_matches('/')),
                    bytes,
                })
            })
            .collect::<Result<Vec<_>, NodeError>>()?;
        Ok(Outputs::new().with("files", Artifacts { files }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::read_ubo2003::{self, ReadUbo2003};
    use crate::types::{Direction, DirectionPair};
    use mesoflow_testkit::node::OutputsExt;
    use std::sync::Arc;

    fn sample_btf() -> Btf {
        let dirs = [(0.0, 0.0), (15.0, 60.0), (75.0, 345.0)];
        let pairs: Vec<DirectionPair> = dirs
            .iter()
            .flat_map(|&(vt, vp)| {
                dirs.iter().map(move |&(lt, lp)| DirectionPair {
                    view: Direction::degrees(vt, vp),
                    light: Direction::degrees(lt, lp),
                })
            })
            .collect();
        let (w, h) = (6, 4);
        let data = (0..pairs.len() * 3 * w * h)
            .map(|i| {
                (crate::support::rng::unit(crate::support::rng::hash(5, &[i as u64])) * 1.7) as f32
            })
            .collect();
        Btf {
            width: w,
            height: h,
            pairs,
            data,
        }
    }

    fn write(btf: &Btf, p: Params, dir: &std::path::Path) {
        let out = mesoflow_testkit::node::run(
            &WriteUbo2003,
            &p,
            &Inputs::new().with("btf", Arc::new(btf.clone())),
        )
        .unwrap();
        let files = out.value::<Artifacts>("files");
        for f in &files.files {
            let path = dir.join(&f.path);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, &f.bytes).unwrap();
        }
    }

    fn read(dir: &std::path::Path, p: read_ubo2003::Params) -> Result<Btf, NodeError> {
        let ctx = NodeContext::detached(None).with_base(dir.to_path_buf());
        mesoflow_testkit::node::run_in(&ctx, &ReadUbo2003, &p, &Inputs::new())
            .map(|o| o.value::<Btf>("btf").clone())
    }

    fn params(path: &str) -> read_ubo2003::Params {
        serde_json::from_value(serde_json::json!({ "path": path })).unwrap()
    }

    #[test]
    fn exr_round_trip_is_bit_identical_and_png_is_within_quantisation() {
        let dir = tempfile::tempdir().unwrap();
        let btf = sample_btf();
        write(
            &btf,
            Params {
                path: "exr".into(),
                format: Format::Exr,
                bits: 8,
            },
            dir.path(),
        );
        let back = read(dir.path(), params("exr")).unwrap();
        assert_eq!(back.pairs, btf.pairs);
        assert_eq!(
            back.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            btf.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        // 16-bit PNG holds linear samples clipped to [0, 1]: half a step is 0.5/65535 ≈ 7.7e-6.
        write(
            &btf,
            Params {
                path: "png".into(),
                format: Format::Png,
                bits: 16,
            },
            dir.path(),
        );
        let back = read(dir.path(), params("png")).unwrap();
        for (a, b) in back.data.iter().zip(&btf.data) {
            assert!((a - b.min(1.0)).abs() <= 0.5 / 65535.0 + 1e-7, "{a} vs {b}");
        }
    }

    #[test]
    fn crops_downsamples_and_subsets() {
        let dir = tempfile::tempdir().unwrap();
        let btf = sample_btf();
        write(
            &btf,
            Params {
                path: "s".into(),
                format: Format::Exr,
                bits: 8,
            },
            dir.path(),
        );
        let mut p = params("s");
        p.crop = Some([2, 0, 4, 4]);
        p.downsample = 2;
        p.views = Some(vec![[15.0, 60.0]]);
        let b = read(dir.path(), p).unwrap();
        assert_eq!((b.width, b.height, b.pairs.len()), (2, 2, 3));
        // Pair 3 of the source (view 15/60, light 0/0), red plane, texel (1, 0): the mean of
        // source texels x 4..6, y 0..2 (computed here from the source directly).
        let src = &btf.data[3 * 3 * 24..];
        let want = (src[4] as f64 + src[5] as f64 + src[6 + 4] as f64 + src[6 + 5] as f64) / 4.0;
        assert!((b.data[1] as f64 - want).abs() < 1e-7);
    }

    #[test]
    fn broken_folders_are_errors_that_say_what_is_wrong() {
        let dir = tempfile::tempdir().unwrap();
        let btf = sample_btf();
        write(
            &btf,
            Params {
                path: "s".into(),
                format: Format::Exr,
                bits: 8,
            },
            dir.path(),
        );
        let s = dir.path().join("s");
        // A missing pair is listed by its angles.
        let gone = s.join("00004_tl015_pl060_tv015_pv060.exr");
        let bytes = std::fs::read(&gone).unwrap();
        std::fs::remove_file(&gone).unwrap();
        let e = read(dir.path(), params("s")).unwrap_err().to_string();
        assert!(
            e.contains("1 of 3 × 3 direction pairs are missing")
                && e.contains("view (θ 15°, φ 60°) light (θ 15°, φ 60°)"),
            "{e}"
        );
        // A duplicate pair (same angles under another index, in a subfolder) names both files.
        std::fs::create_dir_all(s.join("sub")).unwrap();
        std::fs::write(&gone, &bytes).unwrap();
        std::fs::write(s.join("sub/99999_tl015_pl060_tv015_pv060.exr"), &bytes).unwrap();
        let e = read(dir.path(), params("s")).unwrap_err().to_string();
        assert!(
            e.contains("duplicate direction pair") && e.contains("99999_"),
            "{e}"
        );
        std::fs::remove_dir_all(s.join("sub")).unwrap();
        // An undecodable file and an image of the wrong size name the file.
        std::fs::write(&gone, b"not an image").unwrap();
        let e = read(dir.path(), params("s")).unwrap_err().to_string();
        assert!(e.contains("00004_tl015") && e.contains("EXR"), "{e}");
        let small = crate::types::Image {
            width: 2,
            height: 2,
            channels: 3,
            data: vec![0.5; 12],
        };
        std::fs::write(&gone, formats::encode_exr(&small).unwrap()).unwrap();
        let e = read(dir.path(), params("s")).unwrap_err().to_string();
        assert!(
            e.contains("00004_tl015") && e.contains("is 2×2, the other images 6×4"),
            "{e}"
        );
        // NaN pixels name the file and the pixel.
        let mut nan = btf.preview(4);
        nan.data[3 * 7] = f32::NAN;
        std::fs::write(&gone, formats::encode_exr(&nan).unwrap()).unwrap();
        let e = read(dir.path(), params("s")).unwrap_err().to_string();
        assert!(
            e.contains("00004_tl015") && e.contains("pixel (1, 1)"),
            "{e}"
        );
        // No matching files; no folder; over the memory budget (refused before decoding).
        std::fs::create_dir_all(dir.path().join("empty")).unwrap();
        std::fs::write(dir.path().join("empty/readme.txt"), b"x").unwrap();
        let e = read(dir.path(), params("empty")).unwrap_err().to_string();
        assert!(e.contains("no images named like"), "{e}");
        assert!(read(dir.path(), params("nowhere"))
            .unwrap_err()
            .to_string()
            .contains("no such file or folder"));
        std::fs::write(&gone, &bytes).unwrap();
        let mut p = params("s");
        p.memory_budget_gb = Some(1e-6);
        let e = read(dir.path(), p).unwrap_err().to_string();
        assert!(
            e.contains("needs 0.00 GB") || e.contains("over the memory budget"),
            "{e}"
        );
    }
}
