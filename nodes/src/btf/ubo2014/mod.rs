//! The Bonn University binary BTF formats of the UBO2014 database (btflib's layout): parsing
//! every compressed variant into its factors, turning them into a `BtfBasis` without expanding
//! them, and writing the DFMF variant.
//!
//! Layout (little-endian): a signature (`!DFMF08FCR`, `!FMF12FCER`, `!FMF06FCR`, `!FMF06FC`,
//! `!PVF06FCR`, `!PVF06FC`; the longest that matches), then the common header — a meta block
//! (u32 byte size, u32 version, three 80-byte strings, f32 pixels/mm, 3 f32 RGB scale; from
//! version 2 a u32 cosine flag, from 3 a u32 length and XML, from 4 u32 channels and
//! length-prefixed names), the
//! directions (u32 views; per view θ, φ as f32 radians, u32 lights and their θ, φ), u32 width and
//! height, and for signatures ending in R u32 rotations and 3×3 f32 each. Then per variant:
//! - FMF: (12FCER only) u8 header version; ≥ 1: u32 dynamic-range reduction; ≥ 2: u32 × 2 size and
//!   a half-float height map; then u32 components, u8 scalar size, u32 components, u32 rows, u32
//!   columns, S, U (rows × k), S×V (columns × k), matrices row-major.
//! - DFMF: u32 components, i32 colour model, 3 f32 colour mean, 3×3 f32 matrix, then per channel
//!   u8 scalar size, u32 components, rows, columns, S, U, S×V.
//! - PVF: u32 components, u32 view slots, per slot u8 scalar size, u32 components, u32 weights,
//!   u32 dimension, eigenvalues, mean (dimension), C (dimension × k), W (weights × k). The legacy
//!   PVF has the magic int32 301074 after the signature, then u32 components, width, height,
//!   slots and the directions, without the meta block.
//!
//! Indices: texels are column-major (y + h·x), angles light-fastest (l + nL·v), channels fastest
//! where they share a row (c + nC·…). Scalars are IEEE half (2 bytes), single or double.

use crate::types::{BasisBlock, Centring, ColorSpace};
use crate::types::{BtfBasis, Direction, DirectionPair};
use half::f16;

/// A parse error: where in the file (when one place is to blame) and what.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}{what}", offset.map(|o| format!("at byte {o}: ")).unwrap_or_default())]
pub struct FormatError {
    pub offset: Option<usize>,
    pub what: String,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Signature {
    Dfmf08Fcr,
    Fmf12Fcer,
    Fmf06Fcr,
    Fmf06Fc,
    Pvf06Fcr,
    Pvf06Fc,
}

impl Signature {
    pub const ALL: [Signature; 6] = [
        Signature::Dfmf08Fcr,
        Signature::Fmf12Fcer,
        Signature::Fmf06Fcr,
        Signature::Fmf06Fc,
        Signature::Pvf06Fcr,
        Signature::Pvf06Fc,
    ];

    pub fn text(self) -> &'static str {
        match self {
            Signature::Dfmf08Fcr => "!DFMF08FCR",
            Signature::Fmf12Fcer => "!FMF12FCER",
            Signature::Fmf06Fcr => "!FMF06FCR",
            Signature::Fmf06Fc => "!FMF06FC",
            Signature::Pvf06Fcr => "!PVF06FCR",
            Signature::Pvf06Fc => "!PVF06FC",
        }
    }

    fn rotations(self) -> bool {
        self.text().ends_with('R')
    }
}

/// The common header.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    pub signature: Signature,
    /// Whether cos θi is already multiplied into the values (mesoflow's convention).
    pub cosine_in_data: bool,
    pub rgb_scale: [f32; 3],
    pub channels: usize,
    /// View directions, (θ, φ) radians.
    pub views: Vec<[f32; 2]>,
    /// The light directions (the same for every view, as btflib requires).
    pub lights: Vec<[f32; 2]>,
    pub width: usize,
    pub height: usize,
}

/// A truncated SVD: `rows × k` U and `cols × k` S×V, row-major, and the k singular values.
#[derive(Clone, Debug, PartialEq)]
pub struct Factor {
    pub rows: usize,
    pub cols: usize,
    pub s: Vec<f32>,
    pub u: Vec<f32>,
    pub sxv: Vec<f32>,
}

impl Factor {
    pub fn k(&self) -> usize {
        self.s.len()
    }
}

/// One PVF view slot: `dim × k` C, `weights × k` W, the mean over `dim`, eigenvalues.
#[derive(Clone, Debug, PartialEq)]
pub struct PvfSlot {
    pub ev: Vec<f32>,
    pub mean: Vec<f32>,
    pub c: Vec<f32>,
    pub w: Vec<f32>,
    pub dim: usize,
    pub weights: usize,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Payload {
    Fmf {
        /// 0: linear values; otherwise the values are ln(x + 1e-5).
        dynamic_range: u32,
        factor: Factor,
    },
    Dfmf {
        color_model: i32,
        color_mean: [f32; 3],
        /// Row-major.
        color_matrix: [f32; 9],
        channels: Vec<Factor>,
    },
    Pvf {
        slots: Vec<PvfSlot>,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Ubo2014 {
    pub header: Header,
    pub payload: Payload,
}

/// btflib's offset of the logarithmic dynamic-range reduction.
pub const DRR_EPS: f64 = 1e-5;

struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn fail<T>(&self, what: impl Into<String>) -> Result<T, FormatError> {
        Err(FormatError {
            offset: Some(self.at),
            what: what.into(),
        })
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], FormatError> {
        if self.bytes.len() - self.at < n {
            return self.fail(format!(
                "the file ends inside {what} ({n} bytes needed, {} left)",
                self.bytes.len() - self.at
            ));
        }
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }

    fn u8(&mut self, what: &str) -> Result<u8, FormatError> {
        Ok(self.take(1, what)?[0])
    }
    fn u32(&mut self, what: &str) -> Result<u32, FormatError> {
        Ok(u32::from_le_bytes(
            self.take(4, what)?.try_into().unwrap_or([0; 4]),
        ))
    }
    fn i32(&mut self, what: &str) -> Result<i32, FormatError> {
        Ok(i32::from_le_bytes(
            self.take(4, what)?.try_into().unwrap_or([0; 4]),
        ))
    }
    fn f32(&mut self, what: &str) -> Result<f32, FormatError> {
        Ok(f32::from_le_bytes(
            self.take(4, what)?.try_into().unwrap_or([0; 4]),
        ))
    }

    /// A count that must fit in what is left of the file at `bytes_each` bytes per item.
    fn count(&mut self, what: &str, bytes_each: usize) -> Result<usize, FormatError> {
        let n = self.u32(what)? as usize;
        if n.saturating_mul(bytes_each) > self.bytes.len() - self.at {
            return Err(FormatError {
                offset: Some(self.at - 4),
                what: format!(
                    "{what} is {n}, more than the {} bytes left in the file can hold",
                    self.bytes.len() - self.at
                ),
            });
        }
        Ok(n)
    }

    /// `n` scalars of `size` bytes (2: half, 4: single, 8: double) as f32.
    fn scalars(&mut self, n: usize, size: u8, what: &str) -> Result<Vec<f32>, FormatError> {
        let bytes = self.take(n.saturating_mul(size as usize), what)?;
        Ok(match size {
            2 => bytes
                .chunks_exact(2)
                .map(|b| f16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect(),
            4 => bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            _ => bytes
                .chunks_exact(8)
                .map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8])) as f32)
                .collect(),
        })
    }

    fn scalar_size(&mut self, what: &str) -> Result<u8, FormatError> {
        let at = self.at;
        match self.u8(what)? {
            s @ (2 | 4 | 8) => Ok(s),
            s => Err(FormatError {
                offset: Some(at),
                what: format!("{what} is {s}; only 2 (half), 4 and 8 bytes are defined"),
            }),
        }
    }
}

/// The longest known signature the file starts with.
pub fn signature(bytes: &[u8]) -> Option<Signature> {
    Signature::ALL
        .into_iter()
        .filter(|s| bytes.starts_with(s.text().as_bytes()))
        .max_by_key(|s| s.text().len())
}

pub fn parse(bytes: &[u8]) -> Result<Ubo2014, FormatError> {
    let Some(sig) = signature(bytes) else {
        let shown: String = bytes
            .iter()
            .take(10)
            .map(|b| {
                if b.is_ascii_graphic() {
                    *b as char
                } else {
                    '?'
                }
            })
            .collect();
        return Err(FormatError { offset: Some(0), what: format!("the signature \"{shown}\" is none of UBO2014's (!DFMF08FCR, !FMF12FCER, !FMF06FCR, !FMF06FC, !PVF06FCR, !PVF06FC)") });
    };
    let mut c = Cursor {
        bytes,
        at: sig.text().len(),
    };
    let legacy_pvf = matches!(sig, Signature::Pvf06Fc | Signature::Pvf06Fcr)
        && bytes.len() >= c.at + 4
        && i32::from_le_bytes(bytes[c.at..c.at + 4].try_into().unwrap_or([0; 4])) == 301074;
    if legacy_pvf {
        c.at += 4;
        let k = c.u32("the component count")? as usize;
        let width = c.u32("the width")? as usize;
        let height = c.u32("the height")? as usize;
        let slots = c.u32("the view slot count")? as usize;
        let (views, lights) = directions(&mut c)?;
        let header = Header {
            signature: sig,
            cosine_in_data: false,
            rgb_scale: [1.0; 3],
            channels: 3,
            views,
            lights,
            width,
            height,
        };
        let payload = pvf_slots(&mut c, slots, k)?;
        return finish(c, Ubo2014 { header, payload });
    }
    let header = common_header(&mut c, sig)?;
    let payload = match sig {
        Signature::Dfmf08Fcr => {
            c.u32("the component count")?;
            let color_model = c.i32("the colour model")?;
            let color_mean = [
                c.f32("the colour mean")?,
                c.f32("the colour mean")?,
                c.f32("the colour mean")?,
            ];
            let mut color_matrix = [0f32; 9];
            for v in color_matrix.iter_mut() {
                *v = c.f32("the colour matrix")?;
            }
            let channels = (0..header.channels)
                .map(|ch| factor(&mut c, &format!("channel {ch}")))
                .collect::<Result<_, _>>()?;
            Payload::Dfmf {
                color_model,
                color_mean,
                color_matrix,
                channels,
            }
        }
        Signature::Fmf12Fcer | Signature::Fmf06Fcr | Signature::Fmf06Fc => {
            let version = if sig == Signature::Fmf12Fcer {
                c.u8("the FMF header version")?
            } else {
                0
            };
            if version >= 3 {
                return c.fail(format!(
                    "FMF header version {version} is newer than btflib's 2"
                ));
            }
            let dynamic_range = if version >= 1 {
                c.u32("the dynamic-range method")?
            } else {
                0
            };
            if version >= 2 {
                let rows = c.u32("the height map's rows")? as usize;
                let cols = c.u32("the height map's columns")? as usize;
                c.scalars(rows.saturating_mul(cols), 2, "the height map")?;
            }
            c.u32("the component count")?;
            Payload::Fmf {
                dynamic_range,
                factor: factor(&mut c, "the factorisation")?,
            }
        }
        Signature::Pvf06Fcr | Signature::Pvf06Fc => {
            let k = c.u32("the component count")? as usize;
            let slots = c.u32("the view slot count")? as usize;
            pvf_slots(&mut c, slots, k)?
        }
    };
    finish(c, Ubo2014 { header, payload })
}

fn finish(c: Cursor, file: Ubo2014) -> Result<Ubo2014, FormatError> {
    if c.at != c.bytes.len() {
        return c.fail(format!(
            "{} bytes follow the data the header describes",
            c.bytes.len() - c.at
        ));
    }
    check_sizes(&file)?;
    Ok(file)
}

fn common_header(c: &mut Cursor, sig: Signature) -> Result<Header, FormatError> {
    let start = c.at;
    let size = c.u32("the meta block's size")? as usize;
    let version = c.u32("the meta block's version")?;
    c.take(240, "the three 80-byte description strings")?;
    c.f32("pixels per mm")?;
    let rgb_scale = [
        c.f32("the RGB scale")?,
        c.f32("the RGB scale")?,
        c.f32("the RGB scale")?,
    ];
    let cosine_in_data = version > 1 && c.u32("the cosine flag")? != 0;
    if version > 2 {
        let n = c.count("the XML length", 1)?;
        c.take(n, "the XML")?;
    }
    let mut channels = 3;
    if version > 3 {
        channels = c.count("the channel count", 4)?;
        for _ in 0..channels {
            let n = c.count("a channel name's length", 1)?;
            c.take(n, "a channel name")?;
        }
    }
    if c.at - start != size {
        return Err(FormatError {
            offset: Some(start),
            what: format!(
                "the meta block says it is {size} bytes but its fields take {}",
                c.at - start
            ),
        });
    }
    let (views, lights) = directions(c)?;
    let width = c.u32("the width")? as usize;
    let height = c.u32("the height")? as usize;
    if sig.rotations() {
        let n = c.count("the rotation count", 36)?;
        c.take(36 * n, "the rotations")?;
    }
    Ok(Header {
        signature: sig,
        cosine_in_data,
        rgb_scale,
        channels,
        views,
        lights,
        width,
        height,
    })
}

#[allow(clippy::type_complexity)]
fn directions(c: &mut Cursor) -> Result<(Vec<[f32; 2]>, Vec<[f32; 2]>), FormatError> {
    let nv = c.count("the view count", 12)?;
    let mut views = Vec::with_capacity(nv);
    let mut lights: Option<Vec<[f32; 2]>> = None;
    for v in 0..nv {
        views.push([c.f32("a view direction")?, c.f32("a view direction")?]);
        let at = c.at;
        let nl = c.count("a light count", 8)?;
        let these: Vec<[f32; 2]> = (0..nl)
            .map(|_| Ok([c.f32("a light direction")?, c.f32("a light direction")?]))
            .collect::<Result<_, FormatError>>()?;
        match &lights {
            None => lights = Some(these),
            Some(l) if l.len() != nl => {
                return Err(FormatError { offset: Some(at), what: format!("view {v} has {nl} lights, view 0 {}; the lights must be the same for every view", l.len()) });
            }
            Some(_) => {}
        }
    }
    Ok((views, lights.unwrap_or_default()))
}

fn factor(c: &mut Cursor, what: &str) -> Result<Factor, FormatError> {
    let size = c.scalar_size(&format!("{what}'s scalar size"))?;
    let k = c.count(&format!("{what}'s component count"), size as usize)?;
    let rows = c.u32(&format!("{what}'s rows"))? as usize;
    let cols = c.u32(&format!("{what}'s columns"))? as usize;
    let s = c.scalars(k, size, &format!("{what}'s singular values"))?;
    let u = c.scalars(
        rows.saturating_mul(k),
        size,
        &format!("{what}'s U ({rows} × {k})"),
    )?;
    let sxv = c.scalars(
        cols.saturating_mul(k),
        size,
        &format!("{what}'s S×V ({cols} × {k})"),
    )?;
    Ok(Factor {
        rows,
        cols,
        s,
        u,
        sxv,
    })
}

fn pvf_slots(c: &mut Cursor, slots: usize, _k: usize) -> Result<Payload, FormatError> {
    let mut out = Vec::new();
    for v in 0..slots {
        let what = format!("view slot {v}");
        let size = c.scalar_size(&format!("{what}'s scalar size"))?;
        let k = c.count(&format!("{what}'s component count"), size as usize)?;
        let weights = c.u32(&format!("{what}'s weight count"))? as usize;
        let dim = c.u32(&format!("{what}'s dimension"))? as usize;
        let ev = c.scalars(k, size, &format!("{what}'s eigenvalues"))?;
        let mean = c.scalars(dim, size, &format!("{what}'s mean"))?;
        let cm = c.scalars(
            dim.saturating_mul(k),
            size,
            &format!("{what}'s components ({dim} × {k})"),
        )?;
        let w = c.scalars(
            weights.saturating_mul(k),
            size,
            &format!("{what}'s weights ({weights} × {k})"),
        )?;
        out.push(PvfSlot {
            ev,
            mean,
            c: cm,
            w,
            dim,
            weights,
        });
    }
    Ok(Payload::Pvf { slots: out })
}

/// The factor shapes against the header: one of the two layouts each variant allows.
fn check_sizes(f: &Ubo2014) -> Result<(), FormatError> {
    let h = &f.header;
    let (t, nl, nv, nc) = (
        h.width * h.height,
        h.lights.len(),
        h.views.len(),
        h.channels,
    );
    let bad = |what: String| Err(FormatError { offset: None, what });
    if t == 0 || nl == 0 || nv == 0 {
        return bad(format!(
            "the header describes {}×{} texels, {nv} views and {nl} lights: nothing to read",
            h.width, h.height
        ));
    }
    match &f.payload {
        Payload::Fmf { factor, .. } => {
            let ok = (factor.rows == nc * nl * nv && factor.cols == t)
                || (factor.rows == nc * t && factor.cols == nl * nv);
            if !ok {
                return bad(format!("the factorisation is {} × {}; the header asks for {} × {t} (channels·lights·views × texels) or {} × {}", factor.rows, factor.cols, nc * nl * nv, nc * t, nl * nv));
            }
        }
        Payload::Dfmf { channels, .. } => {
            if nc != 3 {
                return bad(format!(
                    "{nc} channels: mesoflow reads three-channel DFMF files"
                ));
            }
            for (i, ch) in channels.iter().enumerate() {
                let ok =
                    (ch.rows == nl * nv && ch.cols == t) || (ch.rows == t && ch.cols == nl * nv);
                if !ok {
                    return bad(format!("channel {i} is {} × {}; the header asks for {} × {t} (lights·views × texels) or the transpose", ch.rows, ch.cols, nl * nv));
                }
            }
        }
        Payload::Pvf { slots } => {
            if slots.len() != nv {
                return bad(format!("{} view slots for {nv} views", slots.len()));
            }
            for (v, s) in slots.iter().enumerate() {
                let ok =
                    (s.dim == nc * nl && s.weights == t) || (s.dim == nc * t && s.weights == nl);
                if !ok {
                    return bad(format!("view slot {v} is {} × {} weights; the header asks for dimension {} with {t} weights or {} with {nl}", s.dim, s.weights, nc * nl, nc * t));
                }
            }
        }
    }
    if nc != 3 {
        return bad(format!("{nc} channels: mesoflow reads RGB BTFs"));
    }
    Ok(())
}

/// Why a file's factors are not a linear RGB (or YCbCr) basis, if they are not.
pub fn nonlinear(f: &Ubo2014) -> Option<String> {
    match &f.payload {
        Payload::Fmf { dynamic_range, .. } if *dynamic_range != 0 => Some(format!("its values are logarithms (dynamic-range method {dynamic_range})")),
        Payload::Dfmf { color_model, .. } if !matches!(color_model, 0 | 1) => Some(format!("its colour model {color_model} ({}) is not linear RGB or YUV", color_model_name(*color_model))),
        Payload::Pvf { slots } if !f.header.cosine_in_data && slots.iter().any(|s| s.weights == f.header.lights.len()) => {
            Some("its images-stacked view slots keep a per-texel mean, which cannot take the cosine factor the file leaves out".into())
        }
        _ => None,
    }
}

pub fn color_model_name(m: i32) -> &'static str {
    match m {
        0 => "RGB",
        1 => "YUV",
        2 => "Lab",
        3 => "PCA",
        4 => "YCoCg",
        5 => "spectral",
        6 => "spectral linear",
        9 => "log Y, UV",
        10 => "log Y, log U, log V",
        11 => "log Y, U/Y, V/Y",
        12 => "log RGB",
        _ => "unknown",
    }
}

fn pairs(h: &Header) -> Vec<DirectionPair> {
    let dir = |d: &[f32; 2]| Direction {
        theta: d[0] as f64,
        phi: d[1] as f64,
    };
    h.views
        .iter()
        .flat_map(|v| {
            h.lights.iter().map(move |l| DirectionPair {
                view: dir(v),
                light: dir(l),
            })
        })
        .collect()
}

/// The factors as a `BtfBasis` in the file's own channel space (labelled RGB, or YCbCr for a YUV
/// DFMF, whose U and V are rescaled to Cb and Cr), texels re-ordered row-major. With
/// `with_cosine`, when the file leaves the cosine out each column is multiplied by cos θi
/// (mesoflow's values include it; blocks with a per-texel mean cannot take it, see `nonlinear`).
/// The caller decides whether the space is really RGB (`nonlinear`).
pub fn to_basis(f: &Ubo2014, with_cosine: bool) -> BtfBasis {
    let h = &f.header;
    let (w, ht, nl) = (h.width, h.height, h.lights.len());
    let t = w * ht;
    let pairs = pairs(h);
    let n = pairs.len();
    // Row-major texel i = y·w + x is the file's y + h·x.
    let file_texel = |i: usize| (i / w) + ht * (i % w);
    let cosine: Vec<f32> = pairs
        .iter()
        .map(|p| {
            if h.cosine_in_data || !with_cosine {
                1.0
            } else {
                p.light.theta.cos() as f32
            }
        })
        .collect();
    let mut color = ColorSpace::Rgb;
    let mut blocks = Vec::new();
    // A block over all pairs: maps from a texel-indexed matrix, basis from an angle-indexed one.
    let block = |channel: Option<u8>,
                 texel_of: &dyn Fn(usize, usize) -> f32,
                 angle_of: &dyn Fn(usize, usize) -> f32,
                 s: &[f32],
                 cols: usize,
                 first_pair: usize,
                 pair_count: usize,
                 mean: Vec<f32>,
                 centring: Centring,
                 scale: f32| {
        let k = s.len();
        let maps = (0..k)
            .flat_map(|kk| (0..t).map(move |i| texel_of(file_texel(i), kk)))
            .collect();
        let basis = (0..k)
            .flat_map(|kk| (0..cols).map(move |j| angle_of(j, kk) * scale))
            .collect::<Vec<f32>>();
        BasisBlock {
            first_pair,
            pair_count,
            channel,
            centring,
            mean,
            maps,
            basis,
            singular: s.to_vec(),
        }
    };
    match &f.payload {
        Payload::Fmf { factor: fa, .. } => {
            let k = fa.k();
            if fa.cols == t {
                // U: (c + 3·pair) × k — exactly the block's column order j = 3·pair + c.
                let mut b = block(
                    None,
                    &|x, kk| fa.sxv[x * k + kk],
                    &|j, kk| fa.u[j * k + kk],
                    &fa.s,
                    3 * n,
                    0,
                    n,
                    vec![0.0; 3 * n],
                    Centring::Columns,
                    1.0,
                );
                scale_columns(&mut b, &cosine, 3);
                blocks.push(b);
            } else {
                for ch in 0..3 {
                    let mut b = block(
                        Some(ch as u8),
                        &|x, kk| fa.u[(ch + 3 * x) * k + kk],
                        &|j, kk| fa.sxv[j * k + kk],
                        &fa.s,
                        n,
                        0,
                        n,
                        vec![0.0; n],
                        Centring::Columns,
                        1.0,
                    );
                    scale_columns(&mut b, &cosine, 1);
                    blocks.push(b);
                }
            }
        }
        Payload::Dfmf {
            color_model,
            channels,
            ..
        } => {
            // YUV's U and V are multiples of Cb and Cr: B − Y = 2.03211·U = 1.772·Cb and
            // R − Y = 1.13983·V = 1.402·Cr.
            let yuv = *color_model == 1;
            if yuv {
                color = ColorSpace::YCbCr;
            }
            for (ch, fa) in channels.iter().enumerate() {
                let k = fa.k();
                let scale = match (yuv, ch) {
                    (true, 1) => (2.03211 / 1.772) as f32,
                    (true, 2) => (1.13983 / 1.402) as f32,
                    _ => 1.0,
                };
                let mut b = if fa.cols == t {
                    block(
                        Some(ch as u8),
                        &|x, kk| fa.sxv[x * k + kk],
                        &|j, kk| fa.u[j * k + kk],
                        &fa.s,
                        n,
                        0,
                        n,
                        vec![0.0; n],
                        Centring::Columns,
                        scale,
                    )
                } else {
                    block(
                        Some(ch as u8),
                        &|x, kk| fa.u[x * k + kk],
                        &|j, kk| fa.sxv[j * k + kk],
                        &fa.s,
                        n,
                        0,
                        n,
                        vec![0.0; n],
                        Centring::Columns,
                        scale,
                    )
                };
                scale_columns(&mut b, &cosine, 1);
                blocks.push(b);
            }
        }
        Payload::Pvf { slots } => {
            for (v, s) in slots.iter().enumerate() {
                let k = s.ev.len();
                let first = v * nl;
                if s.weights == t {
                    // Light field: C is (c + 3·l) × k, the block's column order; W is texels × k.
                    let mean = s.mean.clone();
                    let mut b = block(
                        None,
                        &|x, kk| s.w[x * k + kk],
                        &|j, kk| s.c[j * k + kk],
                        &s.ev,
                        3 * nl,
                        first,
                        nl,
                        mean,
                        Centring::Columns,
                        1.0,
                    );
                    scale_columns(&mut b, &cosine[first..first + nl], 3);
                    b.singular = s.ev.clone();
                    blocks.push(b);
                } else {
                    for ch in 0..3 {
                        let mean = (0..t).map(|i| s.mean[ch + 3 * file_texel(i)]).collect();
                        let b = block(
                            Some(ch as u8),
                            &|x, kk| s.c[(ch + 3 * x) * k + kk],
                            &|j, kk| s.w[j * k + kk],
                            &s.ev,
                            nl,
                            first,
                            nl,
                            mean,
                            Centring::Texels,
                            1.0,
                        );
                        blocks.push(b);
                    }
                }
            }
        }
    }
    BtfBasis {
        width: w,
        height: ht,
        pairs,
        color,
        blocks,
    }
}

/// Multiplies a block's columns (and a per-column mean) by the cosine of their pair.
fn scale_columns(b: &mut BasisBlock, cosine: &[f32], channels: usize) {
    if cosine.iter().all(|c| *c == 1.0) {
        return;
    }
    let cols = b.cols();
    for (j, m) in b.mean.iter_mut().enumerate().take(cols) {
        *m *= cosine[j / channels];
    }
    for kk in 0..b.rank() {
        for j in 0..cols {
            b.basis[kk * cols + j] *= cosine[j / channels];
        }
    }
}

/// The non-linear steps after the factors' product, per texel value triple in the file's channel
/// space: dynamic-range restoration and the DFMF colour models btflib defines.
pub fn finish_values(f: &Ubo2014, v: [f64; 3]) -> Result<[f64; 3], String> {
    let yuv = |[y, u, w]: [f64; 3]| {
        [
            y + 1.13983 * w,
            y - 0.39465 * u - 0.5806 * w,
            y + 2.03211 * u,
        ]
    };
    match &f.payload {
        Payload::Fmf { dynamic_range, .. } => Ok(if *dynamic_range != 0 {
            v.map(|x| x.exp() - DRR_EPS)
        } else {
            v
        }),
        Payload::Pvf { .. } => Ok(v),
        Payload::Dfmf {
            color_model,
            color_mean,
            color_matrix: m,
            ..
        } => match color_model {
            0 | 1 => Ok(v),
            3 => {
                let m = m.map(|x| x as f64);
                Ok([0, 1, 2].map(|c| {
                    v[0] * m[c] + v[1] * m[3 + c] + v[2] * m[6 + c] + color_mean[c] as f64
                }))
            }
            4 => Ok([v[0] + v[1] - v[2], v[0] + v[2], v[0] - v[1] - v[2]]),
            9 => Ok(yuv([v[0].exp() - DRR_EPS, v[1], v[2]])),
            10 => {
                let lg = |x: f64| x.signum() * (x.abs() + DRR_EPS.ln()).exp();
                Ok(yuv([v[0].exp() - DRR_EPS, lg(v[1]), lg(v[2])]))
            }
            11 => {
                let y = v[0].exp() - DRR_EPS;
                Ok(yuv([y, v[1] * (y + DRR_EPS), v[2] * (y + DRR_EPS)]))
            }
            12 => Ok(v.map(|x| x.exp() - DRR_EPS)),
            m => Err(format!(
                "colour model {m} ({}) is not supported",
                color_model_name(*m)
            )),
        },
    }
}

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
