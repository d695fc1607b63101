//! Encoders and decoders for the file formats mesoflow exchanges: PNG (8/16-bit, sRGB for
//! display), EXR (linear f32), Radiance HDR and JPEG (read only), NPY (f32 arrays, numpy's layout).

use crate::types::Image;
use crate::types::{linear_to_srgb, srgb_to_linear};
use mesoflow_runtime::NodeError;
use std::io::Cursor;
use std::path::Path;

/// A single-channel grid of samples, as read from a file.
pub struct Grid {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

fn ext(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

/// Reads an image as linear f32. 8-bit files are sRGB-decoded; 16-bit and float files are taken
/// as linear (the design brief: sRGB only for 8-bit images).
pub fn read_image(path: &Path) -> Result<Image, NodeError> {
    let (img, eight_bit) = read_samples(path)?;
    if !eight_bit {
        return Ok(img);
    }
    let alpha = img.channels == 4;
    let data = img
        .data
        .iter()
        .enumerate()
        .map(|(i, &c)| {
            if alpha && i % 4 == 3 {
                c
            } else {
                srgb_to_linear(c)
            }
        })
        .collect();
    Ok(Image { data, ..img })
}

/// The samples as stored, normalised to [0, 1] for integer formats, with no transfer function;
/// and whether the file had 8-bit samples.
fn read_samples(path: &Path) -> Result<(Image, bool), NodeError> {
    if !path.is_file() {
        return Err(NodeError::file(path, "no such file"));
    }
    if ext(path) == "exr" {
        return Ok((read_exr(path)?, false));
    }
    let img = image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| NodeError::file(path, e))?
        .decode()
        .map_err(|e| NodeError::file(path, format!("cannot decode: {e}")))?;
    let eight_bit = matches!(
        img.color(),
        image::ColorType::L8
            | image::ColorType::La8
            | image::ColorType::Rgb8
            | image::ColorType::Rgba8
    );
    let (width, height) = (img.width() as usize, img.height() as usize);
    if width == 0 || height == 0 {
        return Err(NodeError::file(
            path,
            format!("the image is empty ({width} × {height})"),
        ));
    }
    let grey = img.color().channel_count() <= 2;
    let (channels, data): (usize, Vec<f32>) = match (grey, img.color().has_alpha()) {
        (true, false) => (1, img.to_luma32f().into_raw()),
        (_, true) => (4, img.to_rgba32f().into_raw()),
        (false, false) => (3, img.to_rgb32f().into_raw()),
    };
    Ok((
        Image {
            width,
            height,
            channels,
            data,
        },
        eight_bit,
    ))
}

fn read_exr(path: &Path) -> Result<Image, NodeError> {
    use exr::prelude::*;
    // The header's window against the memory budget before any pixel is read (issue 43: a
    // 445-byte file declaring 100 000² pixels aborted on a 40 GB allocation).
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| NodeError::file(path, format!("cannot decode EXR: {e}")))?;
    if let Some(h) = meta.headers.first() {
        let (w, hh) = (h.layer_size.width() as u64, h.layer_size.height() as u64);
        let channels = h.channels.list.len().max(1) as u64;
        // Decoded as f32, then interleaved into the image: two copies.
        let bytes = crate::support::memory::product(&[w, hh, channels, 4, 2]);
        crate::support::memory::check(bytes, &format!("the EXR image of {w} × {hh} pixels"), None)
            .map_err(|e| NodeError::file(path, e.to_string()))?;
    }
    let img = read_first_flat_layer_from_file(path)
        .map_err(|e| NodeError::file(path, format!("cannot decode EXR: {e}")))?;
    let layer = &img.layer_data;
    let (width, height) = (layer.size.width(), layer.size.height());
    if width == 0 || height == 0 {
        return Err(NodeError::file(
            path,
            format!("the image is empty ({width} × {height})"),
        ));
    }
    let find = |name: &str| {
        layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.eq_case_insensitive(name))
    };
    let wanted: Vec<_> = match (find("R"), find("G"), find("B"), find("A"), find("Y")) {
        (Some(r), Some(g), Some(b), a, _) => [Some(r), Some(g), Some(b), a]
            .into_iter()
            .flatten()
            .collect(),
        (_, _, _, _, Some(y)) => vec![y],
        _ => layer.channel_data.list.iter().take(1).collect(),
    };
    if wanted.is_empty() {
        return Err(NodeError::file(path, "EXR layer has no channels"));
    }
    let planes: Vec<Vec<f32>> = wanted
        .iter()
        .map(|c| c.sample_data.values_as_f32().collect())
        .collect();
    let channels = planes.len();
    let mut data = vec![0f32; width * height * channels];
    for (c, plane) in planes.iter().enumerate() {
        for (i, v) in plane.iter().enumerate() {
            data[i * channels + c] = *v;
        }
    }
    Ok(crate::types::Image {
        width,
        height,
        channels,
        data,
    })
}

/// Reads a single-channel grid: a grey image (first channel of a colour one), EXR, or 2-D NPY.
pub fn read_grey(path: &Path) -> Result<Grid, NodeError> {
    if ext(path) == "npy" {
        return read_npy_2d(path);
    }
    // Heights are values, not colours: the stored samples, without any sRGB decoding.
    let (img, _) = read_samples(path)?;
    let data = img
        .data
        .chunks_exact(img.channels)
        .map(|px| px[0])
        .collect();
    Ok(Grid {
        width: img.width,
        height: img.height,
        data,
    })
}

fn read_npy_2d(path: &Path) -> Result<Grid, NodeError> {
    let a = super::npy::read(path, 2, "(H, W)")?;
    // Finite as f64 is not finite as f32 (1e300 became inf).
    if let Some(i) = a.data.iter().position(|v| v.abs() > f32::MAX as f64) {
        return Err(NodeError::file(
            path,
            format!("value {i} is {}, beyond single precision", a.data[i]),
        ));
    }
    Ok(Grid {
        width: a.shape[1],
        height: a.shape[0],
        data: a.data.into_iter().map(|v| v as f32).collect(),
    })
}

/// PNG bytes of a linear image, 8 or 16 bits per sample. 8-bit samples are sRGB-encoded (alpha
/// stays linear); 16-bit samples are linear, as the design's rule (sRGB only for 8-bit images) and
/// `read_image` have it, so a 16-bit PNG reads back as what was written.
pub fn encode_png(img: &Image, bits: u8) -> Result<Vec<u8>, String> {
    let encode = |i: usize, c: f32| {
        if img.channels == 4 && i % 4 == 3 {
            if c.is_nan() {
                0.0
            } else {
                c.clamp(0.0, 1.0)
            }
        } else {
            linear_to_srgb(c)
        }
    };
    let (w, h) = (img.width as u32, img.height as u32);
    let dynamic = if bits == 16 {
        let raw: Vec<u16> = img
            .data
            .iter()
            .map(|&c| {
                let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
                (c * 65535.0).round() as u16
            })
            .collect();
        match img.channels {
            1 => image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, raw)
                .map(image::DynamicImage::from),
            3 => image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(w, h, raw)
                .map(image::DynamicImage::from),
            _ => image::ImageBuffer::<image::Rgba<u16>, _>::from_raw(w, h, raw)
                .map(image::DynamicImage::from),
        }
    } else {
        let raw: Vec<u8> = img
            .data
            .iter()
            .enumerate()
            .map(|(i, &c)| (encode(i, c) * 255.0).round() as u8)
            .collect();
        match img.channels {
            1 => image::ImageBuffer::<image::Luma<u8>, _>::from_raw(w, h, raw)
                .map(image::DynamicImage::from),
            3 => image::ImageBuffer::<image::Rgb<u8>, _>::from_raw(w, h, raw)
                .map(image::DynamicImage::from),
            _ => image::ImageBuffer::<image::Rgba<u8>, _>::from_raw(w, h, raw)
                .map(image::DynamicImage::from),
        }
    }
    .ok_or("image size does not match its data")?;
    let mut out = Cursor::new(Vec::new());
    dynamic
        .write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| e.to_string())?;
    Ok(out.into_inner())
}

/// EXR bytes of a linear image: channels Y, RGB or RGBA as f32, lossless ZIP compression.
pub fn encode_exr(img: &Image) -> Result<Vec<u8>, String> {
    use exr::prelude::*;
    let names: &[&str] = match img.channels {
        1 => &["Y"],
        3 => &["R", "G", "B"],
        _ => &["R", "G", "B", "A"],
    };
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = names
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let plane = img
                .data
                .iter()
                .skip(c)
                .step_by(img.channels)
                .copied()
                .collect();
            AnyChannel::new(*name, FlatSamples::F32(plane))
        })
        .collect();
    let layer = Layer::new(
        (img.width, img.height),
        LayerAttributes::named("main"),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list),
    );
    let mut out = Cursor::new(Vec::new());
    exr::image::Image::from_layer(layer)
        .write()
        .to_buffered(&mut out)
        .map_err(|e| e.to_string())?;
    Ok(out.into_inner())
}

/// NPY bytes (little-endian f32, C order) of an array of the given shape.
pub fn encode_npy<T: npyz::Serialize + npyz::AutoSerialize + Copy>(
    shape: &[usize],
    data: &[T],
) -> Result<Vec<u8>, String> {
    use npyz::WriterBuilder;
    let shape: Vec<u64> = shape.iter().map(|&s| s as u64).collect();
    let mut out = Cursor::new(Vec::new());
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&shape)
        .writer(&mut out)
        .begin_nd()
        .map_err(|e| e.to_string())?;
    w.extend(data.iter().copied()).map_err(|e| e.to_string())?;
    w.finish().map_err(|e| e.to_string())?;
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(channels: usize) -> Image {
        let (w, h) = (5, 3);
        let data = (0..w * h * channels)
            .map(|i| i as f32 / (w * h * channels) as f32)
            .collect();
        Image {
            width: w,
            height: h,
            channels,
            data,
        }
    }

    #[test]
    fn exr_round_trip_is_bit_exact() {
        let dir = tempfile::tempdir().unwrap();
        for c in [1, 3, 4] {
            let img = ramp(c);
            let path = dir.path().join(format!("t{c}.exr"));
            std::fs::write(&path, encode_exr(&img).unwrap()).unwrap();
            assert_eq!(read_image(&path).unwrap(), img);
        }
    }

    #[test]
    fn png16_round_trip_is_within_quantisation() {
        // 16-bit linear quantisation: half a step is 0.5/65535 ≈ 7.7e-6.
        let dir = tempfile::tempdir().unwrap();
        let img = ramp(3);
        let path = dir.path().join("t.png");
        std::fs::write(&path, encode_png(&img, 16).unwrap()).unwrap();
        let back = read_image(&path).unwrap();
        assert_eq!((back.width, back.height, back.channels), (5, 3, 3));
        for (a, b) in img.data.iter().zip(&back.data) {
            assert!(
                (b - a.clamp(0.0, 1.0)).abs() <= 0.5 / 65535.0 + 1e-7,
                "{a} {b}"
            );
        }
    }

    #[test]
    fn npy_is_what_numpy_writes() {
        // The NPY v1.0 header for a (2, 3) little-endian float32 C-order array, per numpy's spec.
        let bytes = encode_npy(&[2, 3], &[1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        // And f64 (diffusion profiles): '<f8', eight bytes per value.
        let wide = encode_npy(&[1, 2], &[0.5f64, 1e-300]).unwrap();
        assert!(String::from_utf8_lossy(&wide[10..]).contains("'descr': '<f8'"));
        assert_eq!(&wide[wide.len() - 8..], &1e-300f64.to_le_bytes());
        assert_eq!(&bytes[..6], b"\x93NUMPY");
        let header = String::from_utf8_lossy(&bytes[10..]).to_string();
        assert!(
            header.contains("'descr': '<f4'") && header.contains("'shape': (2, 3"),
            "{header}"
        );
        assert_eq!(&bytes[bytes.len() - 4..], &6f32.to_le_bytes());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.npy");
        std::fs::write(&path, &bytes).unwrap();
        let g = read_grey(&path).unwrap();
        assert_eq!((g.width, g.height, g.data[5]), (3, 2, 6.0));
    }

    #[test]
    fn grey_png_heights_are_raw_samples() {
        // A 16-bit grey PNG holding 0, 1000, 65535 reads back as those values / 65535 exactly
        // (no transfer function on heights), and an 8-bit one as value / 255.
        let dir = tempfile::tempdir().unwrap();
        let p16 = dir.path().join("h16.png");
        image::ImageBuffer::<image::Luma<u16>, _>::from_raw(3, 1, vec![0u16, 1000, 65535])
            .unwrap()
            .save(&p16)
            .unwrap();
        let g = read_grey(&p16).unwrap();
        assert_eq!(g.data, vec![0.0, 1000.0 / 65535.0, 1.0]);
        let p8 = dir.path().join("h8.png");
        image::ImageBuffer::<image::Luma<u8>, _>::from_raw(2, 1, vec![51u8, 255])
            .unwrap()
            .save(&p8)
            .unwrap();
        assert_eq!(read_grey(&p8).unwrap().data, vec![51.0 / 255.0, 1.0]);
    }

    #[test]
    fn missing_and_garbage_files_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        assert!(read_image(&dir.path().join("none.png")).is_err());
        let path = dir.path().join("bad.png");
        std::fs::write(&path, b"not a png").unwrap();
        let e = read_image(&path).unwrap_err().to_string();
        assert!(e.contains("bad.png"), "{e}");
    }
}
