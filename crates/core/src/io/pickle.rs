//! A safe reader for the subset of Python pickles that FLAME model and mask
//! files use: dicts, lists, tuples, strings, numbers, numpy arrays (any byte
//! order, C or Fortran order), scipy.sparse csc/csr matrices and chumpy `Ch`
//! wrappers, from Python 2 (latin-1 strings) or 3 pickles, protocols 0-5.
//!
//! It never executes anything: `GLOBAL`/`STACK_GLOBAL` resolve only to the
//! constructors listed in [`ALLOWED_GLOBALS`], interpreted here as data
//! builders; any other global is an error naming it. Allocations are bounded by
//! the input size (every element comes from at least one input byte, and arrays
//! must match the bytes that carry them).

use std::collections::HashMap;
use std::rc::Rc;

/// The globals a pickle may name (module, name); everything else is refused.
pub const ALLOWED_GLOBALS: &[(&str, &str)] = &[
    ("numpy.core.multiarray", "_reconstruct"),
    ("numpy._core.multiarray", "_reconstruct"),
    ("numpy.core.multiarray", "scalar"),
    ("numpy._core.multiarray", "scalar"),
    ("numpy", "ndarray"),
    ("numpy", "dtype"),
    ("copy_reg", "_reconstructor"),
    ("copyreg", "_reconstructor"),
    ("__builtin__", "object"),
    ("builtins", "object"),
    ("scipy.sparse.csc", "csc_matrix"),
    ("scipy.sparse._csc", "csc_matrix"),
    ("scipy.sparse.csr", "csr_matrix"),
    ("scipy.sparse._csr", "csr_matrix"),
    ("chumpy.ch", "Ch"),
    ("_codecs", "encode"),
    ("numpy.core.numeric", "_frombuffer"),
    ("numpy._core.numeric", "_frombuffer"),
    // chumpy 0.70 keeps `_dirty_vars = set()` in every Ch's state; protocols
    // 0-3 write a set as a call of the builtin on a list.
    ("__builtin__", "set"),
    ("builtins", "set"),
    ("__builtin__", "frozenset"),
    ("builtins", "frozenset"),
];

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

    fn kind(&self) -> &'static str {
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

/// Most nesting accepted (lists of lists…), so hostile input cannot overflow the stack.
const MAX_DEPTH: usize = 64;

struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or("pickle ends early")?;
        let s = &self.data[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn byte(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
    fn u16(&mut self) -> Result<usize, String> {
        let b = self.take(2)?;
        Ok(u16::from_le_bytes([b[0], b[1]]) as usize)
    }
    fn u32(&mut self) -> Result<usize, String> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    }
    fn u64(&mut self) -> Result<usize, String> {
        let b = self.take(8)?;
        usize::try_from(u64::from_le_bytes(b.try_into().unwrap()))
            .map_err(|_| "length overflows".to_string())
    }
    fn line(&mut self) -> Result<&'a str, String> {
        let rest = &self.data[self.pos..];
        let end = rest
            .iter()
            .position(|&b| b == b'\n')
            .ok_or("pickle line has no end")?;
        self.pos += end + 1;
        std::str::from_utf8(&rest[..end]).map_err(|_| "pickle line is not text".to_string())
    }
}

/// Decodes the body of a protocol-0 `STRING`: Python 2's `repr` of a byte
/// string (`\\`, `\'`, `\n`, `\xhh`, octal `\ooo`…). numpy arrays pickled with
/// protocol 0 carry their raw bytes this way.
fn unescape(body: &str) -> Result<Vec<u8>, String> {
    let bytes = body.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        i += 1;
        if b != b'\\' {
            out.push(b);
            continue;
        }
        let e = *bytes.get(i).ok_or("STRING ends in a backslash")?;
        i += 1;
        match e {
            b'\\' | b'\'' | b'"' => out.push(e),
            b'n' => out.push(b'\n'),
            b'r' => out.push(b'\r'),
            b't' => out.push(b'\t'),
            b'a' => out.push(7),
            b'b' => out.push(8),
            b'f' => out.push(12),
            b'v' => out.push(11),
            b'\n' => {}
            b'x' => {
                let hex = body.get(i..i + 2).ok_or("STRING has a short \\x escape")?;
                out.push(u8::from_str_radix(hex, 16).map_err(|_| "STRING has a bad \\x escape")?);
                i += 2;
            }
            b'0'..=b'7' => {
                let mut v = (e - b'0') as u32;
                for _ in 0..2 {
                    match bytes.get(i) {
                        Some(d @ b'0'..=b'7') => {
                            v = v * 8 + (d - b'0') as u32;
                            i += 1;
                        }
                        _ => break,
                    }
                }
                out.push(v as u8);
            }
            other => {
                out.push(b'\\');
                out.push(other);
            }
        }
    }
    Ok(out)
}

/// Decodes a protocol-0 `UNICODE` line (Python's raw-unicode-escape: only
/// `\\uXXXX` and `\\UXXXXXXXX` are escapes).
fn raw_unicode_unescape(line: &str) -> Result<String, String> {
    let mut out = String::with_capacity(line.len());
    let mut rest = line;
    while let Some(at) = rest.find('\\') {
        out.push_str(&rest[..at]);
        let tail = &rest[at..];
        let width = match tail.as_bytes().get(1) {
            Some(b'u') => 4,
            Some(b'U') => 8,
            _ => {
                out.push('\\');
                rest = &tail[1..];
                continue;
            }
        };
        let code = tail
            .get(2..2 + width)
            .and_then(|h| u32::from_str_radix(h, 16).ok())
            .and_then(char::from_u32)
            .ok_or("UNICODE has a bad escape")?;
        out.push(code);
        rest = &tail[2 + width..];
    }
    out.push_str(rest);
    Ok(out)
}

fn latin1(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| b as char).collect()
}

fn utf8(bytes: &[u8]) -> Result<String, String> {
    String::from_utf8(bytes.to_vec()).map_err(|_| "pickle string is not UTF-8".to_string())
}

fn allowed(module: &str, name: &str) -> Result<Value, String> {
    ALLOWED_GLOBALS
        .iter()
        .find(|(m, n)| *m == module && *n == name)
        .map(|(m, n)| Value::Global(m, n))
        .ok_or_else(|| {
            format!(
                "pickle refers to '{}.{}', which visage does not load (only numpy arrays, scipy sparse matrices, chumpy arrays and plain data)",
                crate::text::printable(module),
                crate::text::printable(name)
            )
        })
}

/// Applies an allowed callable to arguments (REDUCE / NEWOBJ).
fn call(callable: Value, args: Vec<Value>) -> Result<Value, String> {
    let Value::Global(module, name) = callable else {
        return Err(format!(
            "pickle calls {} instead of a class",
            callable.kind()
        ));
    };
    match name {
        "_reconstruct" => {
            // numpy: _reconstruct(ndarray, shape, dtype code) then BUILD with the data.
            Ok(Value::Object {
                class: ("numpy", "ndarray"),
                args,
                state: None,
            })
        }
        "_reconstructor" => {
            // copy_reg._reconstructor(cls, base, state): an empty cls instance.
            match args.first() {
                Some(Value::Global(m, n)) => Ok(Value::Object {
                    class: (m, n),
                    args: Vec::new(),
                    state: None,
                }),
                _ => Err("copy_reg._reconstructor without a class".into()),
            }
        }
        "dtype" => {
            let code = match args.first() {
                Some(Value::Str(s)) => s.clone(),
                Some(Value::Bytes(b)) => latin1(b),
                _ => return Err("numpy.dtype without a type code".into()),
            };
            let (big, bare) = match code.as_bytes().first() {
                Some(b'>') => (true, &code[1..]),
                Some(b'<' | b'|' | b'=') => (false, &code[1..]),
                _ => (false, code.as_str()),
            };
            let dtype = Dtype::parse(bare).ok_or_else(|| {
                format!(
                    "numpy dtype '{}' is not supported",
                    crate::text::printable(&code)
                )
            })?;
            Ok(Value::Dtype(dtype, big))
        }
        "scalar" => {
            // numpy scalar(dtype, raw bytes)
            match (args.first(), args.get(1)) {
                (Some(Value::Dtype(d, big)), Some(Value::Bytes(b))) if b.len() == d.size() => {
                    Ok(Value::Float(d.decode(b, *big)))
                }
                (Some(Value::Dtype(d, big)), Some(Value::Str(s))) if s.len() == d.size() => {
                    let b: Vec<u8> = s.chars().map(|c| c as u32 as u8).collect();
                    Ok(Value::Float(d.decode(&b, *big)))
                }
                _ => Err("malformed numpy scalar".into()),
            }
        }
        "encode" => {
            // Python 3 writes bytes in protocol 2 as _codecs.encode(text, 'latin1').
            match (args.first(), args.get(1)) {
                (Some(Value::Str(text)), Some(Value::Str(enc)))
                    if enc == "latin1" || enc == "latin-1" =>
                {
                    Ok(Value::Bytes(Rc::new(bytes_of(&Value::Str(text.clone()))?)))
                }
                (Some(Value::Str(text)), _) => Ok(Value::Bytes(Rc::new(text.as_bytes().to_vec()))),
                _ => Err("malformed _codecs.encode".into()),
            }
        }
        "_frombuffer" => {
            // numpy protocol 5: _frombuffer(buffer, dtype, shape, order)
            let (Some(buf), Some(Value::Dtype(dtype, big)), Some(shape), order) =
                (args.first(), args.get(1), args.get(2), args.get(3))
            else {
                return Err("malformed numpy _frombuffer".into());
            };
            let shape = match shape {
                Value::List(dims) => dims.iter().map(usize_of).collect::<Result<Vec<_>, _>>()?,
                other => vec![usize_of(other)?],
            };
            let fortran = matches!(order, Some(Value::Str(o)) if o == "F");
            Ok(Value::Array(Rc::new(NdArray::from_bytes(
                shape,
                *dtype,
                *big,
                fortran,
                &bytes_of(buf)?,
            )?)))
        }
        "set" | "frozenset" => match args.as_slice() {
            // set() or set(iterable): read as the list of its items.
            [] => Ok(Value::List(Vec::new())),
            [Value::List(items)] => Ok(Value::List(items.clone())),
            _ => Err(format!("malformed {name}() in the pickle")),
        },
        "object" | "ndarray" | "csc_matrix" | "csr_matrix" | "Ch" => Ok(Value::Object {
            class: (module, name),
            args,
            state: None,
        }),
        _ => Err(format!("cannot call {module}.{name}")),
    }
}

fn bytes_of(v: &Value) -> Result<Vec<u8>, String> {
    match v {
        Value::Bytes(b) => Ok(b.to_vec()),
        // Python 2 str read with latin-1: one char per byte.
        Value::Str(s) => s
            .chars()
            .map(|c| u8::try_from(c as u32).map_err(|_| "array data is not bytes".to_string()))
            .collect(),
        _ => Err(format!("array data is {}", v.kind())),
    }
}

fn usize_of(v: &Value) -> Result<usize, String> {
    match v {
        Value::Int(i) if *i >= 0 => Ok(*i as usize),
        _ => Err(format!("expected a size, found {}", v.kind())),
    }
}

/// Completes an object with its BUILD state.
fn build(object: Value, state: Value) -> Result<Value, String> {
    let Value::Object { class, args, .. } = object else {
        return Err(format!("pickle builds {}", object.kind()));
    };
    match class {
        ("numpy", "ndarray") => {
            // state = (version, shape, dtype, is_fortran, raw data)
            let Value::List(items) = &state else {
                return Err("numpy array state is not a tuple".into());
            };
            let items = if items.len() == 5 {
                &items[1..]
            } else {
                &items[..]
            };
            if items.len() != 4 {
                return Err("numpy array state has the wrong length".into());
            }
            let shape = match &items[0] {
                Value::List(dims) => dims.iter().map(usize_of).collect::<Result<Vec<_>, _>>()?,
                other => vec![usize_of(other)?],
            };
            let Value::Dtype(dtype, big) = items[1] else {
                return Err(format!("numpy array dtype is {}", items[1].kind()));
            };
            let fortran = matches!(items[2], Value::Bool(true) | Value::Int(1));
            let raw = bytes_of(&items[3])?;
            Ok(Value::Array(Rc::new(NdArray::from_bytes(
                shape, dtype, big, fortran, &raw,
            )?)))
        }
        ("numpy", "dtype") => Ok(Value::Object {
            class,
            args,
            state: Some(Box::new(state)),
        }),
        (_, "csc_matrix") | (_, "csr_matrix") => {
            let field = |k: &str| {
                state
                    .get(k)
                    .ok_or_else(|| format!("sparse matrix without '{k}'"))
            };
            let shape = field("_shape").or_else(|_| field("shape"))?.as_array()?;
            if shape.data.len() != 2 || shape.data.iter().any(|&d| !(0.0..=1e9).contains(&d)) {
                return Err("sparse matrix shape is not two sizes".into());
            }
            let ints = |a: NdArray| -> Result<Vec<usize>, String> {
                a.data
                    .iter()
                    .map(|&x| {
                        if x >= 0.0 && x.fract() == 0.0 {
                            Ok(x as usize)
                        } else {
                            Err("sparse index is not a size".to_string())
                        }
                    })
                    .collect()
            };
            Ok(Value::Sparse(Rc::new(SparseMatrix {
                shape: (shape.data[0] as usize, shape.data[1] as usize),
                column_major: class.1 == "csc_matrix",
                data: field("data")?.as_array()?.data,
                indices: ints(field("indices")?.as_array()?)?,
                indptr: ints(field("indptr")?.as_array()?)?,
            })))
        }
        _ => Ok(Value::Object {
            class,
            args,
            state: Some(Box::new(state)),
        }),
    }
}

/// Where an object lives in the machine's heap.
type NodeId = usize;

/// An object in the pickle machine's heap. Containers hold references, so the
/// memo, `DUP` and `GET` share one object as Python does: an `APPEND`,
/// `SETITEM` or `BUILD` after a `PUT` is seen through every reference.
enum Node {
    /// A finished value (scalars, strings, classes, arrays, dtypes, objects).
    Done(Value),
    /// A list, tuple or set.
    Seq(Vec<NodeId>),
    /// A dict, in insertion order, with the position of each string key.
    Map(Vec<(NodeId, NodeId)>, HashMap<String, usize>),
}

/// The pickle machine: its heap, stack, marks and memo, and a budget on how
/// many values turning the heap into a tree may produce (so shared references
/// cannot expand a small file into an enormous tree).
struct Machine {
    heap: Vec<Node>,
    stack: Vec<NodeId>,
    marks: Vec<usize>,
    memo: HashMap<usize, NodeId>,
    budget: usize,
}

impl Machine {
    fn alloc(&mut self, node: Node) -> NodeId {
        self.heap.push(node);
        self.heap.len() - 1
    }

    fn leaf(&mut self, v: Value) {
        let id = self.alloc(Node::Done(v));
        self.stack.push(id);
    }

    fn pop(&mut self) -> Result<NodeId, String> {
        if self.marks.last().is_some_and(|&m| m == self.stack.len()) {
            return Err("pickle pops past a MARK".into());
        }
        self.stack
            .pop()
            .ok_or_else(|| "pickle stack underflow".into())
    }

    fn top(&self) -> Result<NodeId, String> {
        self.stack
            .last()
            .copied()
            .ok_or_else(|| "pickle stack underflow".into())
    }

    fn pop_mark(&mut self) -> Result<Vec<NodeId>, String> {
        let at = self.marks.pop().ok_or("pickle MARK missing")?;
        Ok(self.stack.split_off(at))
    }

    /// The string a node holds, when it is a finished string (dict keys).
    fn string(&self, id: NodeId) -> Option<&str> {
        match &self.heap[id] {
            Node::Done(Value::Str(s)) => Some(s),
            _ => None,
        }
    }

    /// Adds children to the list, set or dict at `target` (a later equal
    /// string key replaces the earlier value, as in a Python dict).
    fn extend(&mut self, target: NodeId, children: Vec<NodeId>, what: &str) -> Result<(), String> {
        if let Node::Map(..) = self.heap[target] {
            if children.len() % 2 != 0 {
                return Err(format!("{what} with an odd number of items"));
            }
            for pair in children.chunks(2) {
                let key = self.string(pair[0]).map(str::to_owned);
                let Node::Map(items, index) = &mut self.heap[target] else {
                    unreachable!("checked above")
                };
                match key.as_ref().and_then(|k| index.get(k)) {
                    Some(&at) => items[at].1 = pair[1],
                    None => {
                        if let Some(k) = key {
                            index.insert(k, items.len());
                        }
                        items.push((pair[0], pair[1]));
                    }
                }
            }
            return Ok(());
        }
        match &mut self.heap[target] {
            Node::Seq(items) => {
                items.extend(children);
                Ok(())
            }
            Node::Done(v) => Err(format!("{what} on {}", v.kind())),
            Node::Map(..) => unreachable!("handled above"),
        }
    }

    /// Turns a heap object into a value tree, charging every value made to the
    /// budget and refusing nesting deeper than [`MAX_DEPTH`] (which also stops
    /// an object that contains itself).
    fn value(&mut self, id: NodeId, depth: usize) -> Result<Value, String> {
        if depth > MAX_DEPTH {
            return Err("pickle nests too deeply (or an object contains itself)".into());
        }
        self.budget = self
            .budget
            .checked_sub(1)
            .ok_or("pickle references expand beyond its size")?;
        match &self.heap[id] {
            Node::Done(v) => Ok(v.clone()),
            Node::Seq(items) => {
                let items = items.clone();
                let values = items
                    .into_iter()
                    .map(|c| self.value(c, depth + 1))
                    .collect::<Result<_, _>>()?;
                Ok(Value::List(values))
            }
            Node::Map(items, _) => {
                let items = items.clone();
                let mut pairs = Vec::with_capacity(items.len());
                for (k, v) in items {
                    pairs.push((self.value(k, depth + 1)?, self.value(v, depth + 1)?));
                }
                Ok(Value::Dict(pairs))
            }
        }
    }

    /// Pushes a new sequence made of `items`.
    fn push_seq(&mut self, items: Vec<NodeId>) {
        let id = self.alloc(Node::Seq(items));
        self.stack.push(id);
    }
}

/// Parses a pickle into a value.
pub fn parse(data: &[u8]) -> super::Result<Value> {
    let mut r = Reader { data, pos: 0 };
    let mut m = Machine {
        heap: Vec::new(),
        stack: Vec::new(),
        marks: Vec::new(),
        memo: HashMap::new(),
        budget: data.len().saturating_mul(4) + 4096,
    };
    loop {
        let op = r.byte()?;
        match op {
            0x80 => {
                let proto = r.byte()?;
                if proto > 5 {
                    return Err(format!("pickle protocol {proto} is not supported").into());
                }
            }
            0x95 => {
                r.take(8)?; // FRAME length: frames are only a hint
            }
            b'.' => {
                let root = m.pop()?;
                return Ok(m.value(root, 0)?);
            }
            b'(' => m.marks.push(m.stack.len()),
            b'0' => {
                m.pop()?;
            }
            b'1' => {
                m.pop_mark()?;
            }
            b'2' => {
                let top = m.top()?;
                m.stack.push(top);
            }
            b'N' => m.leaf(Value::None),
            0x88 => m.leaf(Value::Bool(true)),
            0x89 => m.leaf(Value::Bool(false)),
            b'I' => {
                let line = r.line()?;
                let v = match line {
                    "01" => Value::Bool(true),
                    "00" => Value::Bool(false),
                    _ => Value::Int(line.trim().parse().map_err(|_| "bad INT")?),
                };
                m.leaf(v);
            }
            b'L' => {
                let line = r.line()?.trim().trim_end_matches('L');
                m.leaf(Value::Int(line.parse().map_err(|_| "integer too large")?));
            }
            b'J' => {
                let b = r.take(4)?;
                m.leaf(Value::Int(
                    i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as i64
                ));
            }
            b'K' => {
                let v = r.byte()? as i64;
                m.leaf(Value::Int(v));
            }
            b'M' => {
                let v = r.u16()? as i64;
                m.leaf(Value::Int(v));
            }
            0x8a | 0x8b => {
                let n = if op == 0x8a {
                    r.byte()? as usize
                } else {
                    r.u32()?
                };
                let b = r.take(n)?;
                if n > 8 {
                    return Err("integer too large".into());
                }
                let mut v: i64 = 0;
                for (i, &byte) in b.iter().enumerate() {
                    v |= (byte as i64) << (8 * i);
                }
                if n > 0 && n < 8 && b[n - 1] & 0x80 != 0 {
                    v -= 1i64 << (8 * n);
                }
                m.leaf(Value::Int(v));
            }
            b'F' => {
                let v = r.line()?.trim().parse().map_err(|_| "bad FLOAT")?;
                m.leaf(Value::Float(v));
            }
            b'G' => {
                let b = r.take(8)?;
                m.leaf(Value::Float(f64::from_be_bytes(b.try_into().unwrap())));
            }
            b'S' => {
                let line = r.line()?.trim_end_matches('\r');
                let quoted = line.len() >= 2
                    && (line.starts_with('\'') && line.ends_with('\'')
                        || line.starts_with('"') && line.ends_with('"'));
                if !quoted {
                    return Err("bad STRING".into());
                }
                m.leaf(Value::Str(latin1(&unescape(&line[1..line.len() - 1])?)));
            }
            b'T' | b'U' => {
                let n = if op == b'T' {
                    r.u32()?
                } else {
                    r.byte()? as usize
                };
                let v = latin1(r.take(n)?);
                m.leaf(Value::Str(v));
            }
            b'V' => {
                let v = raw_unicode_unescape(r.line()?)?;
                m.leaf(Value::Str(v));
            }
            b'X' | 0x8c | 0x8d => {
                let n = match op {
                    b'X' => r.u32()?,
                    0x8c => r.byte()? as usize,
                    _ => r.u64()?,
                };
                let v = utf8(r.take(n)?)?;
                m.leaf(Value::Str(v));
            }
            b'B' | b'C' | 0x8e | 0x96 => {
                let n = match op {
                    b'B' => r.u32()?,
                    b'C' => r.byte()? as usize,
                    _ => r.u64()?,
                };
                let v = r.take(n)?.to_vec();
                m.leaf(Value::Bytes(Rc::new(v)));
            }
            // Empty tuple, list and set (sets are read as lists).
            b')' | b']' | 0x8f => m.push_seq(Vec::new()),
            b'}' => {
                let id = m.alloc(Node::Map(Vec::new(), HashMap::new()));
                m.stack.push(id);
            }
            // TUPLE, LIST and FROZENSET from the items above the mark.
            b't' | b'l' | 0x91 => {
                let items = m.pop_mark()?;
                m.push_seq(items);
            }
            0x85..=0x87 => {
                let n = (op - 0x84) as usize;
                let floor = m.marks.last().copied().unwrap_or(0);
                if m.stack.len() < floor + n {
                    return Err("pickle stack underflow".into());
                }
                let items = m.stack.split_off(m.stack.len() - n);
                m.push_seq(items);
            }
            b'd' => {
                let items = m.pop_mark()?;
                let id = m.alloc(Node::Map(Vec::new(), HashMap::new()));
                m.extend(id, items, "DICT")?;
                m.stack.push(id);
            }
            b'a' => {
                let v = m.pop()?;
                let target = m.top()?;
                m.extend(target, vec![v], "APPEND")?;
            }
            // APPENDS and ADDITEMS.
            b'e' | 0x90 => {
                let items = m.pop_mark()?;
                let target = m.top()?;
                m.extend(target, items, "APPENDS")?;
            }
            b's' => {
                let v = m.pop()?;
                let k = m.pop()?;
                let target = m.top()?;
                m.extend(target, vec![k, v], "SETITEM")?;
            }
            b'u' => {
                let items = m.pop_mark()?;
                let target = m.top()?;
                m.extend(target, items, "SETITEMS")?;
            }
            b'g' | b'h' | b'j' => {
                let k: usize = match op {
                    b'g' => r.line()?.trim().parse().map_err(|_| "bad GET")?,
                    b'h' => r.byte()? as usize,
                    _ => r.u32()?,
                };
                let id = *m.memo.get(&k).ok_or("pickle memo miss")?;
                m.stack.push(id);
            }
            b'p' | b'q' | b'r' | 0x94 => {
                let k: usize = match op {
                    b'p' => r.line()?.trim().parse().map_err(|_| "bad PUT")?,
                    b'q' => r.byte()? as usize,
                    b'r' => r.u32()?,
                    _ => m.memo.len(),
                };
                let top = m.top()?;
                m.memo.insert(k, top);
            }
            b'c' => {
                let module = r.line()?.to_string();
                let name = r.line()?.to_string();
                m.leaf(allowed(&module, &name)?);
            }
            0x93 => {
                let name = m.pop()?;
                let module = m.pop()?;
                match (m.string(module), m.string(name)) {
                    (Some(a), Some(b)) => {
                        let global = allowed(a, b)?;
                        m.leaf(global);
                    }
                    _ => return Err("STACK_GLOBAL needs two strings".into()),
                }
            }
            b'R' | 0x81 | 0x92 => {
                if op == 0x92 {
                    m.pop()?; // keyword arguments: none of the allowed constructors needs them
                }
                let args = m.pop()?;
                let callable = m.pop()?;
                let Node::Seq(_) = m.heap[args] else {
                    return Err("call arguments are not a tuple".into());
                };
                let Value::List(args) = m.value(args, 0)? else {
                    unreachable!("a sequence becomes a list")
                };
                let callable = m.value(callable, 0)?;
                let v = call(callable, args)?;
                m.leaf(v);
            }
            b'b' => {
                let state = m.pop()?;
                let object = m.top()?;
                let state = m.value(state, 0)?;
                let Node::Done(current) = &mut m.heap[object] else {
                    return Err("pickle builds a container".into());
                };
                let built = match std::mem::replace(current, Value::None) {
                    Value::Dtype(d, _) => {
                        let big = matches!(&state, Value::List(items) if matches!(items.get(1), Some(Value::Str(o)) if o == ">"));
                        Value::Dtype(d, big)
                    }
                    o => build(o, state)?,
                };
                // Built in place: every memo reference to the object sees its state.
                m.heap[object] = Node::Done(built);
            }
            b'i' | b'o' | b'P' | b'Q' | 0x82..=0x84 => {
                return Err(format!(
                    "pickle opcode 0x{op:02x} (code execution or persistent ids) is refused"
                )
                .into());
            }
            _ => {
                return Err(
                    format!("unknown pickle opcode 0x{op:02x} at byte {}", r.pos - 1).into(),
                )
            }
        }
    }
}

/// Reads a pickle file.
pub fn read(path: &std::path::Path) -> super::Result<Value> {
    let data = super::read_file(path)?;
    parse(&data).map_err(|e| e.in_file(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pickles written by real numpy/scipy (tests/data/make_pickles.py).
    #[test]
    fn reads_pickles_written_by_real_numpy_and_scipy() {
        for protocol in [2, 4, 5] {
            let path = crate::io::test_data(&format!("real-protocol{protocol}.pkl"));
            let v = read(&path).unwrap_or_else(|e| panic!("protocol {protocol}: {e}"));
            let t = v.get("v_template").unwrap().as_array().unwrap();
            assert_eq!(t.shape, vec![4, 3]);
            assert!((t.data[11] - 1.1).abs() < 1e-12);
            assert_eq!(
                v.get("f").unwrap().as_array().unwrap().data,
                vec![0.0, 1.0, 2.0, 0.0, 2.0, 3.0]
            );
            let s = v.get("shapedirs").unwrap().as_array().unwrap();
            assert_eq!((s.shape.clone(), s.data[23]), (vec![4, 3, 2], 23.0));
            let j = v.get("J_regressor").unwrap().as_array().unwrap();
            assert_eq!(j.data, vec![0.5, 0.5, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
            assert_eq!(
                v.get("fortran").unwrap().as_array().unwrap().data,
                vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
            );
            assert_eq!(
                v.get("big_endian").unwrap().as_array().unwrap().data,
                vec![0.0, 1.0, 2.0]
            );
            assert_eq!(
                v.get("rows").unwrap().as_array().unwrap().data,
                vec![0.0, 2.0, 3.0, 0.0]
            );
            assert_eq!(v.get("name"), Some(&Value::Str("flame".into())));
            assert_eq!(
                v.get("weights").unwrap().as_array().unwrap().data,
                vec![0.25, 0.75]
            );
            assert_eq!(v.get("scalar"), Some(&Value::Float(2.5)));
            // One array under two keys: the second key is a memo reference.
            let linspace = vec![0.0, 0.25, 0.5, 0.75, 1.0];
            for key in ["shared_a", "shared_b"] {
                let a = v.get(key).unwrap().as_array();
                assert_eq!(
                    a.map(|a| a.data),
                    Ok(linspace.clone()),
                    "protocol {protocol} {key}"
                );
            }
            // Big-endian arrays whose dtype objects are memo references.
            assert_eq!(
                v.get("big_a").unwrap().as_array().unwrap().data,
                vec![0.5, 1.5, 2.5, 3.5],
                "protocol {protocol}"
            );
            assert_eq!(
                v.get("big_b").unwrap().as_array().unwrap().data,
                vec![0.0, 1000.0, 2000.0],
                "protocol {protocol}"
            );
            let Some(Value::List(dirty)) = v.get("dirty") else {
                panic!("protocol {protocol}: the set is not read as a list")
            };
            assert_eq!(dirty.len(), 2);
        }
    }

    /// Python shares a memoised object: changes made after `PUT` (items
    /// appended, state built) are seen through every later `GET`.
    #[test]
    fn memo_references_share_the_object() {
        // d = {}; l = []; d['a'] = l; l.append(7); d['b'] = l  (PUT before APPEND)
        let p = b"\x80\x02}q\x00(X\x01\x00\x00\x00a]q\x01K\x07aX\x01\x00\x00\x00bh\x01u.";
        let v = parse(p).unwrap();
        assert_eq!(v.get("a"), Some(&Value::List(vec![Value::Int(7)])));
        assert_eq!(v.get("b"), Some(&Value::List(vec![Value::Int(7)])));
        // A big-endian dtype memoised before BUILD sets its byte order, then reused.
        let dtype_then_get = b"\x80\x02cnumpy\ndtype\nX\x02\x00\x00\x00f8K\x00K\x01\x87Rq\x05(K\x03X\x01\x00\x00\x00>NNNJ\xff\xff\xff\xffJ\xff\xff\xff\xffK\x00tb0h\x05.";
        assert_eq!(
            parse(dtype_then_get).unwrap(),
            Value::Dtype(Dtype::F64, true)
        );
        // A later value for the same key replaces the earlier one, as in Python.
        let twice = b"\x80\x02}(X\x01\x00\x00\x00kK\x01X\x01\x00\x00\x00kK\x02u.";
        assert_eq!(
            parse(twice).unwrap(),
            Value::Dict(vec![(Value::Str("k".into()), Value::Int(2))])
        );
        // A list that contains itself is refused, not followed forever.
        let e = parse(b"\x80\x02]q\x00h\x00a.").unwrap_err().to_string();
        assert!(e.contains("contains itself"), "{e}");
    }

    #[test]
    fn protocol_zero_strings_and_unicode_unescape() {
        let v =
            parse(b"(dp0\nS'raw'\np1\nS'\\x00\\x01\\\\\\'\\n\\t'\np2\nsVname\\u00e9\np3\nI1\ns.")
                .unwrap();
        assert_eq!(v.get("raw"), Some(&Value::Str("\u{0}\u{1}\\'\n\t".into())));
        assert_eq!(v.get("name\u{e9}"), Some(&Value::Int(1)));
        assert!(parse(b"S'unterminated\n.").is_err());
        assert!(parse(b"S'bad \\xZZ'\n.").is_err());
    }

    /// FLAME-layout pickles written by the real chumpy 0.70 under Python 2.7
    /// (tests/data/chumpy/make_chumpy_flame.py): Ch state holds `set()`.
    #[test]
    fn reads_pickles_written_by_real_chumpy() {
        let v = read(&crate::io::test_data("chumpy/generic_model_p0.pkl")).unwrap();
        for key in ["shapedirs", "posedirs", "J", "weights"] {
            let Some(Value::Object {
                class,
                state: Some(state),
                ..
            }) = v.get(key)
            else {
                panic!("{key} is not a chumpy object")
            };
            assert_eq!(*class, ("chumpy.ch", "Ch"));
            assert!(
                matches!(state.get("_dirty_vars"), Some(Value::List(d)) if d == &vec![Value::Str("x".into())])
            );
        }
        assert_eq!(
            v.get("shapedirs").unwrap().as_array().unwrap().shape,
            vec![60, 3, 4]
        );
        assert_eq!(v.get("bs_style"), Some(&Value::Str("lbs".into())));
        let masks = read(&crate::io::test_data("chumpy/generic_masks_p0.pkl")).unwrap();
        let ring = masks
            .get("lip_outside_ring_lower")
            .unwrap()
            .as_array()
            .unwrap();
        assert_eq!(ring.data, (15..30).map(|i| i as f64).collect::<Vec<_>>());
    }

    /// Damaged copies of real pickles (bytes flipped, cut, spliced) parse or
    /// fail with a message — never panic, loop or blow up.
    #[test]
    fn damaged_real_pickles_never_panic() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
        let files = [
            "real-protocol2.pkl",
            "real-protocol5.pkl",
            "chumpy/generic_masks_p0.pkl",
        ];
        for file in files {
            let original = std::fs::read(crate::io::test_data(file)).unwrap();
            for _ in 0..400 {
                let mut bytes = original.clone();
                match rng.random_range(0..3) {
                    0 => {
                        for _ in 0..rng.random_range(1..8) {
                            let at = rng.random_range(0..bytes.len());
                            bytes[at] = rng.random();
                        }
                    }
                    1 => bytes.truncate(rng.random_range(0..bytes.len())),
                    _ => {
                        let from = rng.random_range(0..bytes.len());
                        let to = rng.random_range(0..bytes.len());
                        let len = rng.random_range(1..64).min(bytes.len() - from.max(to));
                        let chunk = bytes[from..from + len].to_vec();
                        bytes.splice(to..to, chunk);
                    }
                }
                if let Ok(v) = parse(&bytes) {
                    let _ = v.as_array();
                    let _ = v.get("v_template").map(Value::as_array);
                }
            }
        }
    }

    #[test]
    fn refuses_code_and_bombs() {
        let e = parse(b"cos\nsystem\n(S'ls'\ntR.").unwrap_err().to_string();
        assert!(e.contains("'os.system'"), "{e}");
        let e = parse(b"\x80\x04\x8c\x08builtins\x8c\x04eval\x93.")
            .unwrap_err()
            .to_string();
        assert!(e.contains("builtins.eval"), "{e}");
        assert!(parse(b"\x80\x02(")
            .unwrap_err()
            .to_string()
            .contains("ends early"));
        assert!(parse(b"\x80\x02cnumpy\ndtype\n\x85R.").is_err());
        // Nesting: 10000 nested lists.
        let mut deep = b"\x80\x02".to_vec();
        deep.extend(std::iter::repeat_n(b'(', 10_000));
        deep.extend(std::iter::repeat_n(b'l', 10_000));
        deep.push(b'.');
        assert!(parse(&deep).unwrap_err().to_string().contains("deeply"));
        // Billion laughs: a list memoised and repeated many times over.
        let mut laughs = b"\x80\x02](K\x01K\x02K\x03K\x04eq\x00".to_vec();
        for _ in 0..40 {
            laughs.extend_from_slice(b"(h\x00h\x00h\x00h\x00h\x00h\x00h\x00h\x00lq\x00");
        }
        laughs.push(b'.');
        assert!(parse(&laughs).unwrap_err().to_string().contains("expand"));
    }
}
