//! `heightfield.normals`: tangent-space normal map of a periodic height field by central
//! differences, n = normalize(−∂h/∂x, −∂h/∂y, 1) with y up the image. A GPU node (wgpu compute)
//! whose CPU path computes the same formula; it proves the GPU lane and the agreement test.

use crate::types::{HeightField, Image, NormalMap};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// The normals shader.
pub(crate) const WGSL: &str = include_str!("normals.wgsl");

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Multiplies every slope (exaggerates or flattens the relief).
    #[schemars(range(min = 0.0, max = 1000.0))]
    pub scale: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params { scale: 1.0 }
    }
}

pub struct Normals;

impl Node for Normals {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "heightfield.normals",
            // 2: edge texels were wrong on the OpenGL backend (signed modulo in the shader).
            version: 2,
            doc: "Normal map of a periodic height field (central differences); GPU compute with a CPU path.",
            device: DevicePreference::Gpu,
            inputs: vec![Port::input("height", HeightField::TYPE, "heights in texels")],
            outputs: vec![
                Port::output("normals", NormalMap::TYPE, "unit normals, tangent frame"),
                Port::output("preview", Image::TYPE, "normals encoded as 0.5·n + 0.5, RGB"),
                Port::output("rms_slope", "Scalar", "root-mean-square slope |∇h| (dimensionless)"),
            ],
            disk_cache: true,
        }
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let hf = inputs.get::<HeightField>("height")?;
        let data = match ctx.gpu() {
            Some(gpu) => normals_gpu(gpu, hf, p.scale as f32)?,
            None => normals_cpu(hf, p.scale as f32),
        };
        ctx.progress(1, 1);
        let normals = NormalMap {
            width: hf.width,
            height: hf.height,
            data,
        };
        let preview = Image {
            width: hf.width,
            height: hf.height,
            channels: 3,
            data: normals.data.iter().map(|c| 0.5 * c + 0.5).collect(),
        };
        let rms = rms_slope(&normals);
        Ok(Outputs::new()
            .with("normals", normals)
            .with("preview", preview)
            .with("rms_slope", Scalar(rms)))
    }
}

pub fn normals_cpu(hf: &HeightField, scale: f32) -> Vec<f32> {
    let w = hf.width;
    let mut out = vec![0f32; w * hf.height * 3];
    out.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        let y = y as isize;
        for x in 0..w {
            let xi = x as isize;
            let dx = (hf.at_wrapped(xi + 1, y) - hf.at_wrapped(xi - 1, y)) * 0.5 * scale;
            let dy = (hf.at_wrapped(xi, y - 1) - hf.at_wrapped(xi, y + 1)) * 0.5 * scale;
            let inv = 1.0 / (dx * dx + dy * dy + 1.0).sqrt();
            row[3 * x..3 * x + 3].copy_from_slice(&[-dx * inv, -dy * inv, inv]);
        }
    });
    out
}

fn normals_gpu(
    gpu: &mesoflow_runtime::Gpu,
    hf: &HeightField,
    scale: f32,
) -> Result<Vec<f32>, NodeError> {
    let mut params = Vec::with_capacity(16);
    params.extend_from_slice(&(hf.width as u32).to_le_bytes());
    params.extend_from_slice(&(hf.height as u32).to_le_bytes());
    params.extend_from_slice(&scale.to_le_bytes());
    params.extend_from_slice(&0f32.to_le_bytes());
    let pass = crate::support::gpu::Pass2d {
        label: "heightfield.normals",
        shader: WGSL,
        entry: "main",
        params: &params,
        input: &hf.data,
        output_len: hf.width * hf.height * 3,
        grid: (hf.width as u32, hf.height as u32),
    };
    crate::support::gpu::compute_2d(gpu, &pass)
}

/// sqrt(mean |∇h|²) recovered from the normals (|∇h|² = (nx² + ny²)/nz²), summed row by row in a
/// fixed order so the value does not depend on thread count.
fn rms_slope(n: &NormalMap) -> f64 {
    let rows: Vec<f64> = n
        .data
        .par_chunks(n.width * 3)
        .map(|row| {
            row.chunks_exact(3)
                .map(|c| ((c[0] * c[0] + c[1] * c[1]) / (c[2] * c[2])) as f64)
                .sum()
        })
        .collect();
    (rows.iter().sum::<f64>() / (n.width * n.height).max(1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tilted_plane_has_its_closed_form_normal() {
        // h = a·x has ∂h/∂x = a wherever the central difference does not cross the seam; the
        // exact normal is (−a, 0, 1)/sqrt(1 + a²).
        let a = 0.5f32;
        let (w, hgt) = (16, 4);
        let data = (0..hgt)
            .flat_map(|_| (0..w).map(move |x| a * x as f32))
            .collect();
        let hf = HeightField {
            width: w,
            height: hgt,
            data,
        };
        let n = normals_cpu(&hf, 1.0);
        let len = (1.0 + a * a).sqrt();
        for x in 1..w - 1 {
            let i = (2 * w + x) * 3;
            assert!(
                (n[i] + a / len).abs() < 1e-6
                    && n[i + 1].abs() < 1e-6
                    && (n[i + 2] - 1.0 / len).abs() < 1e-6
            );
        }
    }

    #[test]
    fn slope_along_v_points_the_normal_down_the_image() {
        // Heights growing towards the top of the image (decreasing row) rise along +y.
        let data = (0..8)
            .flat_map(|y| (0..8).map(move |_| (8 - y) as f32))
            .collect();
        let hf = HeightField {
            width: 8,
            height: 8,
            data,
        };
        let n = normals_cpu(&hf, 1.0);
        let i = (4 * 8 + 4) * 3;
        assert!(n[i + 1] < 0.0 && n[i].abs() < 1e-6);
    }

    #[test]
    fn gpu_and_cpu_paths_agree_on_every_backend() {
        let p = crate::heightfield::procedural::Params {
            pattern: crate::heightfield::procedural::Pattern::Cells,
            size: 96,
            ..Default::default()
        };
        let ctx = NodeContext::detached(None);
        let hf = crate::heightfield::procedural::generate(&ctx, &p).unwrap();
        let cpu = normals_cpu(&hf, 2.0);
        let mut tested = Vec::new();
        // Each backend separately: naga translates the shader differently for each, and a bug in
        // one translation (seen: signed `%` on OpenGL) must not hide behind the preferred one.
        for backends in [wgpu::Backends::PRIMARY, wgpu::Backends::GL] {
            let Ok(gpu) = mesoflow_runtime::Gpu::with_backends(backends) else {
                continue;
            };
            let gpu_out = normals_gpu(&gpu, &hf, 2.0).unwrap();
            // Both paths evaluate the same f32 expression; they may differ only in how sqrt and
            // division round (WGSL allows 2.5 ULP for both), i.e. a few 1e-7 on unit components.
            // 1e-5 leaves a wide margin and still catches any indexing or sign error.
            let max = cpu
                .iter()
                .zip(&gpu_out)
                .map(|(a, b)| (a - b).abs())
                .fold(0f32, f32::max);
            eprintln!(
                "GPU ({}) vs CPU normals: max |difference| = {max:e}",
                gpu.describe()
            );
            assert!(max < 1e-5, "{}: max difference {max}", gpu.describe());
            tested.push(gpu.describe());
        }
        crate::support::gpu::require_tested(tested.len());
    }
}
