//! Writes pickles the way Python 2's cPickle wrote FLAME files (protocol 2):
//! numpy arrays via `numpy.core.multiarray._reconstruct` with memoised dtypes,
//! scipy csc matrices and chumpy `Ch` wrappers via `copy_reg._reconstructor`.
//! Used to generate test fixtures in the real formats.

/// A value to pickle.
pub enum PyObj<'a> {
    /// A string (written as a py2 `str`).
    Str(&'a str),
    /// An int.
    Int(i64),
    /// A float64 array of the given shape (C order).
    F64(Vec<usize>, &'a [f64]),
    /// A float32 array.
    F32(Vec<usize>, &'a [f32]),
    /// A uint32 array.
    U32(Vec<usize>, &'a [u32]),
    /// An int64 array.
    I64(Vec<usize>, &'a [i64]),
    /// A chumpy `Ch` wrapping an array.
    Chumpy(Box<PyObj<'a>>),
    /// A scipy csc matrix: shape, data, indices, indptr.
    Csc((usize, usize), &'a [f64], &'a [i32], &'a [i32]),
    /// A dict with string keys.
    Dict(Vec<(&'a str, PyObj<'a>)>),
}

struct Writer {
    out: Vec<u8>,
    memo: Vec<String>,
}

impl Writer {
    fn op(&mut self, b: u8) {
        self.out.push(b);
    }

    fn binput(&mut self, key: &str) {
        let i = self.memo.len();
        self.memo.push(key.to_string());
        self.op(b'r');
        self.out.extend_from_slice(&(i as u32).to_le_bytes());
    }

    fn memoised(&mut self, key: &str) -> bool {
        if let Some(i) = self.memo.iter().position(|k| k == key) {
            self.op(b'j');
            self.out.extend_from_slice(&(i as u32).to_le_bytes());
            true
        } else {
            false
        }
    }

    fn global(&mut self, module: &str, name: &str) {
        let key = format!("global {module}.{name}");
        if self.memoised(&key) {
            return;
        }
        self.op(b'c');
        self.out
            .extend_from_slice(format!("{module}\n{name}\n").as_bytes());
        self.binput(&key);
    }

    fn str(&mut self, s: &str) {
        self.bytes_str(s.as_bytes());
    }

    fn bytes_str(&mut self, b: &[u8]) {
        if b.len() < 256 {
            self.op(b'U');
            self.op(b.len() as u8);
        } else {
            self.op(b'T');
            self.out.extend_from_slice(&(b.len() as u32).to_le_bytes());
        }
        self.out.extend_from_slice(b);
    }

    fn int(&mut self, v: i64) {
        if (0..256).contains(&v) {
            self.op(b'K');
            self.op(v as u8);
        } else if let Ok(i) = i32::try_from(v) {
            self.op(b'J');
            self.out.extend_from_slice(&i.to_le_bytes());
        } else {
            self.op(0x8a);
            self.op(8);
            self.out.extend_from_slice(&v.to_le_bytes());
        }
    }

    fn tuple(&mut self, items: impl FnOnce(&mut Self)) {
        self.op(b'(');
        items(self);
        self.op(b't');
    }

    fn dtype(&mut self, code: &str) {
        let key = format!("dtype {code}");
        if self.memoised(&key) {
            return;
        }
        self.global("numpy", "dtype");
        self.tuple(|w| {
            w.str(code);
            w.int(0);
            w.int(1);
        });
        self.op(b'R');
        self.tuple(|w| {
            w.int(3);
            w.str(if code == "u1" || code == "b1" {
                "|"
            } else {
                "<"
            });
            w.op(b'N');
            w.op(b'N');
            w.op(b'N');
            w.int(-1);
            w.int(-1);
            w.int(0);
        });
        self.op(b'b');
        self.binput(&key);
    }

    fn array(&mut self, shape: &[usize], code: &str, raw: Vec<u8>) {
        self.global("numpy.core.multiarray", "_reconstruct");
        self.tuple(|w| {
            w.global("numpy", "ndarray");
            w.tuple(|w| w.int(0));
            w.str("b");
        });
        self.op(b'R');
        self.tuple(|w| {
            w.int(1);
            w.tuple(|w| shape.iter().for_each(|&d| w.int(d as i64)));
            w.dtype(code);
            w.op(0x89); // not Fortran order
            w.bytes_str(&raw);
        });
        self.op(b'b');
    }

    fn reconstructor(&mut self, module: &str, class: &str) {
        self.global("copy_reg", "_reconstructor");
        self.tuple(|w| {
            w.global(module, class);
            w.global("__builtin__", "object");
            w.op(b'N');
        });
        self.op(b'R');
    }

    fn value(&mut self, v: &PyObj) {
        match v {
            PyObj::Str(s) => self.str(s),
            PyObj::Int(i) => self.int(*i),
            PyObj::F64(shape, d) => self.array(
                shape,
                "f8",
                d.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            PyObj::F32(shape, d) => self.array(
                shape,
                "f4",
                d.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            PyObj::U32(shape, d) => self.array(
                shape,
                "u4",
                d.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            PyObj::I64(shape, d) => self.array(
                shape,
                "i8",
                d.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            PyObj::Chumpy(inner) => {
                self.reconstructor("chumpy.ch", "Ch");
                self.op(b'}');
                self.op(b'(');
                self.str("x");
                self.value(inner);
                self.op(b'u');
                self.op(b'b');
            }
            PyObj::Csc(shape, data, indices, indptr) => {
                self.reconstructor("scipy.sparse.csc", "csc_matrix");
                self.op(b'}');
                self.op(b'(');
                self.str("_shape");
                self.tuple(|w| {
                    w.int(shape.0 as i64);
                    w.int(shape.1 as i64);
                });
                self.str("data");
                self.value(&PyObj::F64(vec![data.len()], data));
                self.str("indices");
                self.array(
                    &[indices.len()],
                    "i4",
                    indices.iter().flat_map(|x| x.to_le_bytes()).collect(),
                );
                self.str("indptr");
                self.array(
                    &[indptr.len()],
                    "i4",
                    indptr.iter().flat_map(|x| x.to_le_bytes()).collect(),
                );
                self.str("maxprint");
                self.int(50);
                self.op(b'u');
                self.op(b'b');
            }
            PyObj::Dict(items) => {
                self.op(b'}');
                self.op(b'(');
                for (k, v) in items {
                    self.str(k);
                    self.value(v);
                }
                self.op(b'u');
            }
        }
    }
}

/// Serialises a value as a protocol-2 pickle.
pub fn to_pickle(value: &PyObj) -> Vec<u8> {
    let mut w = Writer {
        out: vec![0x80, 2],
        memo: Vec::new(),
    };
    w.value(value);
    w.op(b'.');
    w.out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::pickle::{parse, Value};

    #[test]
    fn written_pickles_read_back() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let f = [0u32, 1, 2];
        let dict = PyObj::Dict(vec![
            ("v_template", PyObj::F64(vec![2, 3], &v)),
            ("f", PyObj::U32(vec![1, 3], &f)),
            (
                "shapedirs",
                PyObj::Chumpy(Box::new(PyObj::F64(vec![2, 3, 1], &v))),
            ),
            (
                "J_regressor",
                PyObj::Csc((2, 3), &[0.5, 0.5], &[0, 1], &[0, 1, 2, 2]),
            ),
            ("bs_style", PyObj::Str("lbs")),
            ("count", PyObj::Int(-7)),
        ]);
        let value = parse(&to_pickle(&dict)).unwrap();
        assert_eq!(value.get("v_template").unwrap().as_array().unwrap().data, v);
        assert_eq!(
            value.get("f").unwrap().as_array().unwrap().shape,
            vec![1, 3]
        );
        assert_eq!(
            value.get("shapedirs").unwrap().as_array().unwrap().shape,
            vec![2, 3, 1]
        );
        let j = value.get("J_regressor").unwrap().as_array().unwrap();
        assert_eq!(j.shape, vec![2, 3]);
        assert_eq!(j.data, vec![0.5, 0.0, 0.0, 0.0, 0.5, 0.0]);
        assert_eq!(value.get("count"), Some(&Value::Int(-7)));
    }
}
