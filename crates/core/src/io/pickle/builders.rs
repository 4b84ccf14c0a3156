//! The Python constructors a pickle may name, interpreted as data builders:
//! numpy arrays, scalars and dtypes, scipy sparse matrices, chumpy `Ch`,
//! `copy_reg` objects, sets and `_codecs.encode`.

use std::rc::Rc;

use super::escapes::latin1;
use super::value::{Dtype, NdArray, SparseMatrix, Value};

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

/// Resolves a `GLOBAL` to one of [`ALLOWED_GLOBALS`], or refuses it with an
/// error naming it.
pub(super) fn allowed(module: &str, name: &str) -> Result<Value, String> {
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
pub(super) fn call(callable: Value, args: Vec<Value>) -> Result<Value, String> {
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
pub(super) fn build(object: Value, state: Value) -> Result<Value, String> {
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
