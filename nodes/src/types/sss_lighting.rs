//! `SssLighting`: what a translucent render shares between views of one object under one light
//! (`sss.lighting`): the lit irradiance samples after the bounces, the bounced light the pixels'
//! near discs take, and `geometry: body`'s solved grid. Plain data; `sss.render` rebuilds its
//! octree, beams and shadow map from it (`nodes/src/sss/render/lighting.rs`).

use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, PartialEq)]
pub struct SssLighting {
    /// The `sss.lighting` parameters it was made with (`geometry` resolved), as JSON.
    pub params: String,
    /// blake3 of the mesh, material and profile it was made for (hex).
    pub made_for: String,
    /// Area each sample stands for, mm².
    pub area_each: f64,
    /// The samples' spacing, mm.
    pub spacing_mm: f64,
    /// Per sample, 9 values: position (mm), unit normal, E·ΔA per channel.
    pub sources: Vec<f64>,
    pub bounced: Option<LightBounced>,
    pub body: Option<BodyGrid>,
    /// The shadow map's depths (world units, row by row; absent without shadows).
    pub shadow: Option<Vec<f64>>,
}

/// The light between parts at a uniform subset of the samples.
#[derive(Clone, Debug, PartialEq)]
pub struct LightBounced {
    /// The nearest-member grid's cell, world units.
    pub cell: f64,
    /// Per member, 3 values: position (world units).
    pub points: Vec<f64>,
    /// Per member, 3 values: transmitted irradiance arriving from other parts.
    pub arriving: Vec<f64>,
}

/// `geometry: body`'s grid and its solution per channel.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyGrid {
    /// Centre of cell (0, 0, 0), mm.
    pub origin: [f64; 3],
    /// Cell, mm.
    pub h: f64,
    pub dims: [usize; 3],
    /// Three channels.
    pub channels: Vec<BodyChannel>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct BodyChannel {
    /// Unknown number per cell, `u32::MAX` outside the extrapolated boundary.
    pub index: Vec<u32>,
    pub psi: Vec<f64>,
    pub d: f64,
    pub zb: f64,
}

impl SssLighting {
    pub const TYPE: &'static str = "SssLighting";

    /// Samples held.
    pub fn len(&self) -> usize {
        self.sources.len() / 9
    }

    pub fn is_empty(&self) -> bool {
        self.sources.is_empty()
    }

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let bad = |m: &str| DecodeError::new(Self::TYPE, m);
        let params = d.str()?;
        let made_for = d.str()?;
        let (area_each, spacing_mm) = (d.f64()?, d.f64()?);
        let sources = d.f64s()?;
        if sources.len() % 9 != 0 {
            return Err(bad("sources are not 9 values each"));
        }
        let bounced = match d.u32()? {
            0 => None,
            _ => {
                let cell = d.f64()?;
                let (points, arriving) = (d.f64s()?, d.f64s()?);
                if points.len() % 3 != 0 || points.len() != arriving.len() {
                    return Err(bad("the bounced light's members and values disagree"));
                }
                Some(LightBounced {
                    cell,
                    points,
                    arriving,
                })
            }
        };
        let body = match d.u32()? {
            0 => None,
            _ => {
                let origin = [d.f64()?, d.f64()?, d.f64()?];
                let h = d.f64()?;
                let dims = [d.u64()?, d.u64()?, d.u64()?].map(|v| v as usize);
                let cells = dims
                    .iter()
                    .try_fold(1usize, |a, &b| a.checked_mul(b))
                    .ok_or_else(|| bad("the grid's cell count overflows"))?;
                let mut channels = Vec::with_capacity(3);
                for _ in 0..3 {
                    let (index, psi) = (d.u32s()?, d.f64s()?);
                    let (dd, zb) = (d.f64()?, d.f64()?);
                    let inside = |&i: &u32| i == u32::MAX || (i as usize) < psi.len();
                    if index.len() != cells || !index.iter().all(inside) {
                        return Err(bad("the grid's unknowns do not match its cells"));
                    }
                    channels.push(BodyChannel {
                        index,
                        psi,
                        d: dd,
                        zb,
                    });
                }
                Some(BodyGrid {
                    origin,
                    h,
                    dims,
                    channels,
                })
            }
        };
        let shadow = match d.u32()? {
            0 => None,
            _ => Some(d.f64s()?),
        };
        Ok(Arc::new(SssLighting {
            shadow,
            params,
            made_for,
            area_each,
            spacing_mm,
            sources,
            bounced,
            body,
        }))
    }
}

impl Value for SssLighting {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        let bounced = self
            .bounced
            .as_ref()
            .map_or(0, |b| 8 * (b.points.len() + b.arriving.len()));
        let body = self.body.as_ref().map_or(0, |b| {
            b.channels
                .iter()
                .map(|c| 4 * c.index.len() + 8 * c.psi.len())
                .sum()
        });
        let shadow = self.shadow.as_ref().map_or(0, |d| 8 * d.len());
        self.params.len() + self.made_for.len() + 8 * self.sources.len() + bounced + body + shadow
    }
    fn encode(&self, out: &mut Encoder) {
        out.str(&self.params)
            .str(&self.made_for)
            .f64(self.area_each)
            .f64(self.spacing_mm)
            .f64s(&self.sources);
        match &self.bounced {
            None => {
                out.u32(0);
            }
            Some(b) => {
                out.u32(1).f64(b.cell).f64s(&b.points).f64s(&b.arriving);
            }
        }
        match &self.body {
            None => {
                out.u32(0);
            }
            Some(b) => {
                out.u32(1);
                for v in b.origin {
                    out.f64(v);
                }
                out.f64(b.h);
                for v in b.dims {
                    out.u64(v as u64);
                }
                for c in &b.channels {
                    out.u32s(&c.index).f64s(&c.psi).f64(c.d).f64(c.zb);
                }
            }
        }
        match &self.shadow {
            None => {
                out.u32(0);
            }
            Some(depth) => {
                out.u32(1).f64s(depth);
            }
        }
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lighting_value_comes_back_from_its_encoding_and_a_damaged_one_is_refused() {
        let v = SssLighting {
            params: "{}".into(),
            made_for: "ab".into(),
            area_each: 0.25,
            spacing_mm: 0.5,
            sources: (0..18).map(f64::from).collect(),
            bounced: Some(LightBounced {
                cell: 0.1,
                points: vec![1.0, 2.0, 3.0],
                arriving: vec![0.5, 0.25, 0.125],
            }),
            body: Some(BodyGrid {
                origin: [0.0, 1.0, 2.0],
                h: 0.5,
                dims: [2, 1, 1],
                channels: (0..3)
                    .map(|c| BodyChannel {
                        index: vec![0, u32::MAX],
                        psi: vec![c as f64],
                        d: 0.3,
                        zb: 0.7,
                    })
                    .collect(),
            }),
            shadow: Some(vec![1.0, f64::INFINITY]),
        };
        let mut out = Encoder::default();
        v.encode(&mut out);
        let mut d = Decoder::new(SssLighting::TYPE, &out.bytes);
        let back = SssLighting::decode(&mut d).unwrap();
        d.finish().unwrap();
        assert_eq!(back.as_any().downcast_ref::<SssLighting>(), Some(&v));
        // Every truncation is an error, never a panic.
        for cut in 0..out.bytes.len() {
            let mut d = Decoder::new(SssLighting::TYPE, &out.bytes[..cut]);
            assert!(SssLighting::decode(&mut d)
                .and_then(|_| d.finish())
                .is_err());
        }
        // An unknown number past the unknowns is refused.
        let mut broken = v.clone();
        broken.body.as_mut().unwrap().channels[1].index[0] = 5;
        let mut out = Encoder::default();
        broken.encode(&mut out);
        assert!(SssLighting::decode(&mut Decoder::new(SssLighting::TYPE, &out.bytes)).is_err());
    }
}
