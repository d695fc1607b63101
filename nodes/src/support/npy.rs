//! Reading NumPy's `.npy` files as numpy users write them: float32 or float64 in either byte
//! order (npyz converts `>f8` as well as `<f8`), C- or Fortran-ordered (a transposed array saved
//! without a copy is Fortran-ordered; it is put back into row-major order here), and never an
//! empty array (a shape with a zero is refused by name instead of failing later in a node).

use mesoflow_runtime::NodeError;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A row-major array of any rank.
pub struct Array {
    pub shape: Vec<usize>,
    pub data: Vec<f64>,
}

/// Reads an array of rank `rank` (`what` names the expected axes for messages, e.g. "(H, W)").
pub fn read(path: &Path, rank: usize, what: &str) -> Result<Array, NodeError> {
    let file = std::fs::File::open(path).map_err(|e| NodeError::file(path, e))?;
    if !file.metadata().is_ok_and(|m| m.is_file()) {
        return Err(NodeError::file(path, "not a regular file"));
    }
    let npy = npyz::NpyFile::new(std::io::BufReader::new(file))
        .map_err(|e| NodeError::file(path, format!("not an NPY file: {e}")))?;
    let shape: Vec<usize> = npy.shape().iter().map(|&d| d as usize).collect();
    if shape.len() != rank {
        return Err(NodeError::file(
            path,
            format!("expected a {rank}-D array {what}, got shape {shape:?}"),
        ));
    }
    if shape.contains(&0) {
        return Err(NodeError::file(
            path,
            format!("the array is empty (shape {shape:?}); expected {what} with no zero axis"),
        ));
    }
    // The element count checked against the file before anything is read (issue 43: a shape of
    // (2³², 2³²) wrapped to nothing and read as an empty array with exit 0).
    let size = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let count = shape
        .iter()
        .try_fold(1usize, |a, &b| a.checked_mul(b))
        .filter(|&n| n.checked_mul(4).is_some_and(|b| (b as u64) <= size));
    let Some(count) = count else {
        return Err(NodeError::file(
            path,
            format!("the shape {shape:?} declares more values than the file's {size} bytes hold"),
        ));
    };
    // Against the memory budget before anything is read (issue 43: it applied to the readers'
    // parameters, not to the arrays themselves): the f64 copy read here and the f32 value a
    // node keeps, 12 bytes a value.
    crate::support::memory::check_param(
        crate::support::memory::product(&[count as u64, 12]),
        &format!("the {shape:?} array"),
        "path",
    )?;
    let fortran = npy.order() == npyz::Order::Fortran;
    let descr = npy.dtype().descr();
    let ty = descr.trim_matches(|c| c == '\'' || c == '"').to_string();
    let data: Vec<f64> = if ty.ends_with("f8") {
        npy.into_vec::<f64>()
            .map_err(|e| NodeError::file(path, e))?
    } else if ty.ends_with("f4") {
        npy.into_vec::<f32>()
            .map_err(|e| NodeError::file(path, e))?
            .into_iter()
            .map(f64::from)
            .collect()
    } else {
        return Err(NodeError::file(
            path,
            format!("expected float32 or float64 samples, got dtype {ty}"),
        ));
    };
    if data.len() != count {
        return Err(NodeError::file(
            path,
            format!(
                "the shape {shape:?} declares {count} values, the file holds {}",
                data.len()
            ),
        ));
    }
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(NodeError::file(
            path,
            format!("element {i} is {}: not finite", data[i]),
        ));
    }
    let data = if fortran {
        to_row_major(&shape, &data)
    } else {
        data
    };
    Ok(Array { shape, data })
}

/// Column-major (first index fastest) to row-major (last index fastest).
fn to_row_major(shape: &[usize], data: &[f64]) -> Vec<f64> {
    let rank = shape.len();
    let mut out = vec![0.0; data.len()];
    let mut index = vec![0usize; rank];
    for v in data {
        // `index` walks in column-major order; its row-major offset is where `v` goes.
        let mut offset = 0;
        for (i, &d) in index.iter().zip(shape) {
            offset = offset * d + i;
        }
        out[offset] = *v;
        for (i, &d) in index.iter_mut().zip(shape) {
            *i += 1;
            if *i < d {
                break;
            }
            *i = 0;
        }
    }
    out
}

/// The parameters of the `*.array` kinds that read one NPY file.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ArrayParams {
    /// NPY file (f32 or f64, C or Fortran order), relative to the graph file.
    pub data: String,
}

/// The array, every element finite, as f32.
pub fn finite_f32(
    path: &Path,
    rank: usize,
    what: &str,
) -> Result<(Vec<usize>, Vec<f32>), NodeError> {
    let a = read(path, rank, what)?;
    if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
        return Err(NodeError::file(
            path,
            format!("element {i} (row-major) is not finite"),
        ));
    }
    Ok((a.shape, a.data.iter().map(|&v| v as f32).collect()))
}

#[cfg(test)]
mod tests {
    use super::*;

    use mesoflow_testkit::npy::npy_bytes as npy;

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    #[test]
    fn fortran_order_and_big_endian_read_as_numpy_means_them() {
        // numpy: a = np.arange(6.).reshape(2, 3); a.T is (3, 2), Fortran-ordered, holding the
        // bytes of a in order 0..6, and means [[0, 3], [1, 4], [2, 5]].
        let dir = tempfile::tempdir().unwrap();
        let payload: Vec<u8> = (0..6).flat_map(|v| (v as f64).to_le_bytes()).collect();
        let p = write(dir.path(), "t.npy", &npy("<f8", true, &[3, 2], &payload));
        let a = read(&p, 2, "(n, D)").unwrap();
        assert_eq!(a.shape, [3, 2]);
        assert_eq!(a.data, [0.0, 3.0, 1.0, 4.0, 2.0, 5.0]);
        // a.astype('>f4'): big-endian float32.
        let payload: Vec<u8> = (0..6).flat_map(|v| (v as f32).to_be_bytes()).collect();
        let p = write(dir.path(), "be.npy", &npy(">f4", false, &[2, 3], &payload));
        let a = read(&p, 2, "(n, D)").unwrap();
        assert_eq!(a.data, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
    }

    #[test]
    fn empty_arrays_and_other_ranks_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        for shape in [[0usize, 3], [3, 0]] {
            let p = write(dir.path(), "e.npy", &npy("<f4", false, &shape, &[]));
            let e = read(&p, 2, "(H, W)").err().unwrap().to_string();
            assert!(e.contains("empty"), "{e}");
        }
        let p = write(dir.path(), "r.npy", &npy("<f4", false, &[4], &[0; 16]));
        let e = read(&p, 2, "(H, W)").err().unwrap().to_string();
        assert!(e.contains("2-D"), "{e}");
        let p = write(dir.path(), "i.npy", &npy("<i4", false, &[1, 1], &[0; 4]));
        let e = read(&p, 2, "(H, W)").err().unwrap().to_string();
        assert!(e.contains("dtype"), "{e}");
    }
}
