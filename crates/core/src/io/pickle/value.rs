//! What a pickle reads as: plain Python values, numpy arrays and dtypes,
//! scipy sparse matrices and objects under construction.

use std::rc::Rc;

/// Element types of numpy arrays we read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    /// bool
    Bool,
    /// int8
    I8,
    /// uint8
    U8,
    /// int16
    I16,
    /// uint16
    U16,
    /// int32
    I32,
    /// uint32
    U32,
    /// int64
    I64,
    /// uint64
    U64,
    /// float16
    F16,
    /// float32
    F32,
    /// float64
    F64,
}

impl Dtype {
    /// Parses a numpy type code without byte order: `f8`, `float64`, `i4`, `u1`, `b1`, `?`…
    pub fn parse(code: &str) -> Option<Dtype> {
        Some(match code {
            "b1" | "?" | "bool" => Dtype::Bool,
            "i1" | "int8" => Dtype::I8,
            "u1" | "uint8" => Dtype::U8,
            "i2" | "int16" => Dtype::I16,
            "u2" | "uint16" => Dtype::U16,
            "i4" | "int32" => Dtype::I32,
            "u4" | "uint32" => Dtype::U32,
            "i8" | "int64" => Dtype::I64,
            "u8" | "uint64" => Dtype::U64,
            "f2" | "float16" => Dtype::F16,
            "f4" | "float32" => Dtype::F32,
            "f8" | "float64" => Dtype::F64,
            _ => return None,
        })
    }

    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            Dtype::Bool | Dtype::I8 | Dtype::U8 => 1,
            Dtype::I16 | Dtype::U16 | Dtype::F16 => 2,
            Dtype::I32 | Dtype::U32 | Dtype::F32 => 4,
            Dtype::I64 | Dtype::U64 | Dtype::F64 => 8,
        }
    }

    /// The numpy type code (`f8`, `i4`, …).
    pub fn code(self) -> &'static str {
        match self {
            Dtype::Bool => "b1",
            Dtype::I8 => "i1",
            Dtype::U8 => "u1",
            Dtype::I16 => "i2",
            Dtype::U16 => "u2",
            Dtype::I32 => "i4",
            Dtype::U32 => "u4",
            Dtype::I64 => "i8",
            Dtype::U64 => "u8",
            Dtype::F16 => "f2",
            Dtype::F32 => "f4",
            Dtype::F64 => "f8",
        }
    }

    /// Decodes one element.
    pub fn decode(self, b: &[u8], big_endian: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                (if big_endian {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Dtype::Bool => (b[0] != 0) as u8 as f64,
            Dtype::I8 => b[0] as i8 as f64,
            Dtype::U8 => b[0] as f64,
            Dtype::I16 => num!(i16, 2),
            Dtype::U16 => num!(u16, 2),
            Dtype::I32 => num!(i32, 4),
            Dtype::U32 => num!(u32, 4),
            Dtype::I64 => num!(i64, 8),
            Dtype::U64 => num!(u64, 8),
            Dtype::F16 => {
                let bits = if big_endian {
                    u16::from_be_bytes([b[0], b[1]])
                } else {
                    u16::from_le_bytes([b[0], b[1]])
                };
                half_to_f64(bits)
            }
            Dtype::F32 => num!(f32, 4),
            Dtype::F64 => num!(f64, 8),
        }
    }
}

fn half_to_f64(bits: u16) -> f64 {
    let sign = if bits & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((bits >> 10) & 0x1f) as i32;
    let frac = (bits & 0x3ff) as f64;
    sign * match exp {
        0 => frac * 2f64.powi(-24),
        31 => {
            if frac == 0.0 {
                f64::INFINITY
            } else {
                f64::NAN
            }
        }
        e => (1.0 + frac / 1024.0) * 2f64.powi(e - 15),
    }
}

/// A dense numpy array, values widened to f64, in C (row-major) order.
#[derive(Clone, Debug, PartialEq)]
pub struct NdArray {
    /// Shape.
    pub shape: Vec<usize>,
    /// Element type in the file.
    pub dtype: Dtype,
    /// Values, row-major.
    pub data: Vec<f64>,
}

impl NdArray {
    /// Number of elements.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// True when there are no elements.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// Decodes raw element bytes (of `shape`, C or Fortran order) into an array.
    pub fn from_bytes(
        shape: Vec<usize>,
        dtype: Dtype,
        big_endian: bool,
        fortran: bool,
        raw: &[u8],
    ) -> Result<NdArray, String> {
        let count = shape
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .ok_or("array shape overflows")?;
        let need = count
            .checked_mul(dtype.size())
            .ok_or("array size overflows")?;
        if raw.len() != need {
            return Err(format!(
                "array of shape {shape:?} ({}) needs {need} bytes but has {}",
                dtype.code(),
                raw.len()
            ));
        }
        let flat: Vec<f64> = raw
            .chunks_exact(dtype.size())
            .map(|c| dtype.decode(c, big_endian))
            .collect();
        let data = if fortran && shape.len() > 1 {
            fortran_to_c(&flat, &shape)
        } else {
            flat
        };
        Ok(NdArray { shape, dtype, data })
    }
}

/// Reorders Fortran-order (first index fastest) data to C order.
fn fortran_to_c(data: &[f64], shape: &[usize]) -> Vec<f64> {
    let n = data.len();
    let mut out = vec![0.0; n];
    let mut index = vec![0usize; shape.len()];
    for value in data {
        // `index` is the multi-index of this Fortran-order element.
        let mut c = 0usize;
        for (d, &i) in index.iter().enumerate() {
            c = c * shape[d] + i;
        }
        out[c] = *value;
        for (d, i) in index.iter_mut().enumerate() {
            *i += 1;
            if *i < shape[d] {
                break;
            }
            *i = 0;
        }
    }
    out
}

/// A compressed sparse matrix (scipy csc or csr).
#[derive(Clone, Debug, PartialEq)]
pub struct SparseMatrix {
    /// Rows and columns.
    pub shape: (usize, usize),
    /// True for csc (indices are rows, indptr over columns), false for csr.
    pub column_major: bool,
    /// Non-zero values.
    pub data: Vec<f64>,
    /// Row (csc) or column (csr) index of each value.
    pub indices: Vec<usize>,
    /// Start of each column (csc) or row (csr) in `data`.
    pub indptr: Vec<usize>,
}

impl SparseMatrix {
    /// The matrix as a dense row-major array, after checking its structure.
    pub fn to_dense(&self) -> Result<NdArray, String> {
        let (rows, cols) = self.shape;
        let outer = if self.column_major { cols } else { rows };
        let inner = if self.column_major { rows } else { cols };
        if self.indptr.len() != outer + 1 || self.indices.len() != self.data.len() {
            return Err("sparse matrix arrays do not fit its shape".into());
        }
        let total = rows
            .checked_mul(cols)
            .filter(|&n| n <= 1 << 28)
            .ok_or("sparse matrix is too large to expand")?;
        let mut dense = vec![0.0; total];
        for o in 0..outer {
            let (a, b) = (self.indptr[o], self.indptr[o + 1]);
            if a > b || b > self.data.len() {
                return Err("sparse matrix index pointers are not increasing".into());
            }
            for k in a..b {
                let i = self.indices[k];
                if i >= inner {
                    return Err(format!("sparse matrix index {i} is out of range"));
                }
                let (r, c) = if self.column_major { (i, o) } else { (o, i) };
                dense[r * cols + c] += self.data[k];
            }
        }
        Ok(NdArray {
            shape: vec![rows, cols],
            dtype: Dtype::F64,
            data: dense,
        })
    }
}

/// A value read from a pickle.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// None
    None,
    /// bool
    Bool(bool),
    /// int (within i64)
    Int(i64),
    /// float
    Float(f64),
    /// str (Python 2 str and unicode, Python 3 str; latin-1 for byte strings)
    Str(String),
    /// bytes
    Bytes(Rc<Vec<u8>>),
    /// list or tuple
    List(Vec<Value>),
    /// dict
    Dict(Vec<(Value, Value)>),
    /// numpy array
    Array(Rc<NdArray>),
    /// scipy sparse matrix
    Sparse(Rc<SparseMatrix>),
    /// A global the pickle named (an allowed constructor).
    Global(&'static str, &'static str),
    /// An object under construction: its class and state.
    Object {
        /// Class (an allowed global).
        class: (&'static str, &'static str),
        /// Constructor arguments.
        args: Vec<Value>,
        /// State set by BUILD.
        state: Option<Box<Value>>,
    },
    /// A numpy dtype.
    Dtype(Dtype, bool),
    /// The MARK sentinel.
    Mark,
}

impl Value {
    /// Looks up a string key in a dict.
    pub fn get(&self, key: &str) -> Option<&Value> {
        match self {
            Value::Dict(items) => items
                .iter()
                .find(|(k, _)| matches!(k, Value::Str(s) if s == key))
                .map(|(_, v)| v),
            _ => None,
        }
    }

    /// The value as an array: numpy arrays, chumpy wrappers, sparse matrices and
    /// nested lists of numbers all qualify.
    pub fn as_array(&self) -> Result<NdArray, String> {
        match self {
            Value::Array(a) => Ok((**a).clone()),
            Value::Sparse(s) => s.to_dense(),
            Value::Object {
                class: ("chumpy.ch", "Ch"),
                state: Some(state),
                ..
            } => state
                .get("x")
                .ok_or_else(|| "chumpy object without its 'x' array".to_string())?
                .as_array(),
            Value::List(items) => {
                let mut data = Vec::new();
                let mut inner: Option<Vec<usize>> = None;
                for item in items {
                    match item {
                        Value::Int(i) => data.push(*i as f64),
                        Value::Float(f) => data.push(*f),
                        Value::Bool(b) => data.push(*b as u8 as f64),
                        other => {
                            let a = other.as_array()?;
                            if inner.get_or_insert_with(|| a.shape.clone()) != &a.shape {
                                return Err("ragged nested list".into());
                            }
                            data.extend(a.data);
                        }
                    }
                }
                let mut shape = vec![items.len()];
                shape.extend(inner.unwrap_or_default());
                Ok(NdArray {
                    shape,
                    dtype: Dtype::F64,
                    data,
                })
            }
            Value::Int(i) => Ok(NdArray {
                shape: vec![],
                dtype: Dtype::I64,
                data: vec![*i as f64],
            }),
            Value::Float(f) => Ok(NdArray {
                shape: vec![],
                dtype: Dtype::F64,
                data: vec![*f],
            }),
            other => Err(format!("expected an array, found {}", other.kind())),
        }
    }

    /// What the value is, in words, for error messages.
    pub(super) fn kind(&self) -> &'static str {
        match self {
            Value::None => "None",
            Value::Bool(_) => "a bool",
            Value::Int(_) => "an int",
            Value::Float(_) => "a float",
            Value::Str(_) => "a string",
            Value::Bytes(_) => "bytes",
            Value::List(_) => "a list",
            Value::Dict(_) => "a dict",
            Value::Array(_) => "an array",
            Value::Sparse(_) => "a sparse matrix",
            Value::Global(..) => "a class",
            Value::Object { .. } => "an object",
            Value::Dtype(..) => "a dtype",
            Value::Mark => "a mark",
        }
    }
}
