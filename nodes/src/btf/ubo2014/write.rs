//! Writing a `BtfBasis` as a DFMF file.

use super::*;
use crate::types::{BtfBasis, Direction, DirectionPair};
use crate::types::{Centring, ColorSpace};
use half::f16;

/// Writes a `BtfBasis` as a DFMF file (`!DFMF08FCR`, meta version 4, cosine in the data, half
/// floats, colour model 0 for RGB or 1 for YCbCr with Cb, Cr rescaled to YUV's U, V). Each
/// channel's U (lights·views × K) and S×V (texels × K) stack every block's components that
/// touch the channel, and a component for each block's mean (its basis row the mean, its map 1;
/// or for a per-texel mean, basis 1 on the block's columns and the mean as the map), so the
/// product is the basis's reconstruction exactly up to half-float rounding. The directions must
/// be a grid: every view with the same lights, view-major.
pub fn write_dfmf(b: &BtfBasis) -> Result<Vec<u8>, String> {
    let (views, lights) = grid(&b.pairs)?;
    let (nl, nv, t) = (lights.len(), views.len(), b.texels());
    let yuv = b.color == ColorSpace::YCbCr;
    let mut out = Vec::new();
    out.extend_from_slice(Signature::Dfmf08Fcr.text().as_bytes());
    // The meta block.
    let names: [&str; 3] = if yuv {
        ["Y", "U", "V"]
    } else {
        ["R", "G", "B"]
    };
    let mut meta = Vec::new();
    meta.extend_from_slice(&4u32.to_le_bytes());
    for s in ["mesoflow", "synthetic", "directional, unit irradiance"] {
        let mut field = [0u8; 80];
        field[..s.len()].copy_from_slice(s.as_bytes());
        meta.extend_from_slice(&field);
    }
    meta.extend_from_slice(&0f32.to_le_bytes());
    for _ in 0..3 {
        meta.extend_from_slice(&1f32.to_le_bytes());
    }
    meta.extend_from_slice(&1u32.to_le_bytes());
    meta.extend_from_slice(&0u32.to_le_bytes());
    meta.extend_from_slice(&3u32.to_le_bytes());
    for n in names {
        meta.extend_from_slice(&(n.len() as u32).to_le_bytes());
        meta.extend_from_slice(n.as_bytes());
    }
    out.extend_from_slice(&((meta.len() + 4) as u32).to_le_bytes());
    out.extend_from_slice(&meta);
    out.extend_from_slice(&(nv as u32).to_le_bytes());
    for v in &views {
        out.extend_from_slice(&(v.theta as f32).to_le_bytes());
        out.extend_from_slice(&(v.phi as f32).to_le_bytes());
        out.extend_from_slice(&(nl as u32).to_le_bytes());
        for l in &lights {
            out.extend_from_slice(&(l.theta as f32).to_le_bytes());
            out.extend_from_slice(&(l.phi as f32).to_le_bytes());
        }
    }
    out.extend_from_slice(&(b.width as u32).to_le_bytes());
    out.extend_from_slice(&(b.height as u32).to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes()); // no rotations
    let channels: Vec<Components> = (0..3).map(|c| channel_components(b, c, t)).collect();
    let k_max = channels.iter().map(|c| c.0.len()).max().unwrap_or(0);
    out.extend_from_slice(&(k_max as u32).to_le_bytes());
    out.extend_from_slice(&(if yuv { 1i32 } else { 0 }).to_le_bytes());
    for _ in 0..3 {
        out.extend_from_slice(&0f32.to_le_bytes());
    }
    // The identity colour matrix, row-major.
    for v in [1f32, 0., 0., 0., 1., 0., 0., 0., 1.] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    // Cb = U·2.03211/1.772 and Cr = V·1.13983/1.402, so U = Cb·1.772/2.03211, V = Cr·1.402/1.13983.
    let to_file = |c: usize| -> f32 {
        match (yuv, c) {
            (true, 1) => (1.772 / 2.03211) as f32,
            (true, 2) => (1.402 / 1.13983) as f32,
            _ => 1.0,
        }
    };
    let half = |out: &mut Vec<u8>, v: f32| out.extend_from_slice(&f16::from_f32(v).to_le_bytes());
    for (c, (s, angle, texel)) in channels.iter().enumerate() {
        let k = s.len();
        out.push(2);
        out.extend_from_slice(&(k as u32).to_le_bytes());
        out.extend_from_slice(&((nl * nv) as u32).to_le_bytes());
        out.extend_from_slice(&(t as u32).to_le_bytes());
        for v in s {
            half(&mut out, *v);
        }
        // U row-major: angle a = l + nL·v (= our pair) then component.
        for a in 0..nl * nv {
            for comp in angle {
                half(&mut out, comp[a] * to_file(c));
            }
        }
        // S×V row-major: file texel y + h·x then component.
        for ft in 0..t {
            let (x, y) = (ft / b.height, ft % b.height);
            for comp in texel {
                half(&mut out, comp[y * b.width + x]);
            }
        }
    }
    Ok(out)
}

/// One channel's DFMF components: singular values, and per component its values over the
/// pairs (U's column) and over the texels (S×V's column).
type Components = (Vec<f32>, Vec<Vec<f32>>, Vec<Vec<f32>>);

/// For channel c: singular values, per component the values over pairs and over texels.
fn channel_components(b: &BtfBasis, c: usize, t: usize) -> Components {
    let n = b.pairs.len();
    let (mut s, mut angle, mut texel) = (vec![], vec![], vec![]);
    for blk in &b.blocks {
        if blk.channel.is_some_and(|ch| ch as usize != c) {
            continue;
        }
        let cols = blk.cols();
        // The block's columns that hold channel c, and their pairs.
        let mine: Vec<(usize, usize)> = (0..cols)
            .filter(|j| blk.column(*j) % 3 == c)
            .map(|j| (j, blk.column(j) / 3))
            .collect();
        let along = |f: &dyn Fn(usize) -> f32| {
            let mut a = vec![0f32; n];
            for &(j, pair) in &mine {
                a[pair] = f(j);
            }
            a
        };
        match blk.centring {
            Centring::Columns => {
                s.push(1.0);
                angle.push(along(&|j| blk.mean[j]));
                texel.push(vec![1.0; t]);
            }
            Centring::Texels => {
                s.push(1.0);
                angle.push(along(&|_| 1.0));
                texel.push(blk.mean.clone());
            }
        }
        for kk in 0..blk.rank() {
            s.push(blk.singular[kk]);
            angle.push(along(&|j| blk.basis[kk * cols + j]));
            texel.push(blk.maps[kk * t..(kk + 1) * t].to_vec());
        }
    }
    (s, angle, texel)
}

/// The pairs as views × lights, view-major, every view with the same lights.
fn grid(pairs: &[DirectionPair]) -> Result<(Vec<Direction>, Vec<Direction>), String> {
    let first_view = pairs
        .first()
        .map(|p| p.view)
        .ok_or("the BTF has no direction pairs")?;
    let nl = pairs.iter().take_while(|p| p.view == first_view).count();
    let lights: Vec<Direction> = pairs[..nl].iter().map(|p| p.light).collect();
    if !pairs.len().is_multiple_of(nl) {
        return Err(format!(
            "{} pairs are not whole views of {nl} lights",
            pairs.len()
        ));
    }
    let views: Vec<Direction> = pairs.chunks(nl).map(|c| c[0].view).collect();
    for (v, chunk) in pairs.chunks(nl).enumerate() {
        if chunk
            .iter()
            .zip(&lights)
            .any(|(p, l)| p.view != views[v] || p.light != *l)
        {
            return Err(format!("view {v}'s pairs are not view 0's lights in the same order: UBO2014 files hold a views × lights grid"));
        }
    }
    Ok((views, lights))
}
