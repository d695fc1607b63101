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

mod basis;
mod parse;
mod write;

pub use basis::{finish_values, to_basis};
pub use parse::{color_model_name, nonlinear, parse, signature};
pub use write::write_dfmf;

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
