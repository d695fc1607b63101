//! Reading a UBO2014 file: the common header, the directions and each variant's factors, with
//! every size checked against the bytes that are there.

use super::*;
use half::f16;

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
    /// A value that is not finite as f32 (inf, NaN, a double beyond f32's range) is refused
    /// (issue 43: they passed into outputs with exit 0).
    fn scalars(&mut self, n: usize, size: u8, what: &str) -> Result<Vec<f32>, FormatError> {
        let at = self.at;
        let bytes = self.take(n.saturating_mul(size as usize), what)?;
        let values: Vec<f32> = match size {
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
        };
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(FormatError {
                offset: Some(at + i * size as usize),
                what: format!("{what}: value {i} is not a finite single-precision number"),
            });
        }
        Ok(values)
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
    let bad = |what: String| Err(FormatError { offset: None, what });
    let (nl, nv, nc) = (h.lights.len(), h.views.len(), h.channels);
    // Every size product checked (issue 43: 3·w·h wrapped, and a file declaring a tiny payload
    // passed this check).
    let product = |parts: &[usize]| {
        parts
            .iter()
            .try_fold(1usize, |a, &b| a.checked_mul(b))
            .filter(|&n| n <= isize::MAX as usize / 8)
    };
    let (Some(t), Some(_)) = (
        product(&[h.width, h.height]),
        product(&[nc, h.width, h.height, nl, nv]),
    ) else {
        return bad(format!(
            "the header's sizes ({}×{} texels, {nc} channels, {nl} lights, {nv} views) overflow",
            h.width, h.height
        ));
    };
    if t == 0 || nl == 0 || nv == 0 {
        return bad(format!(
            "the header describes {}×{} texels, {nv} views and {nl} lights: nothing to read",
            h.width, h.height
        ));
    }
    match &f.payload {
        Payload::Fmf { factor, .. } => {
            if factor.s.is_empty() {
                return bad("the factorisation has rank 0: nothing to reconstruct".into());
            }
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
                if ch.s.is_empty() {
                    return bad(format!("channel {i} has rank 0: nothing to reconstruct"));
                }
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
