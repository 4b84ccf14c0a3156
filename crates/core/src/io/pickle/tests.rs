//! The pickle reader against files written by real numpy, scipy and chumpy,
//! and against hostile input.

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
    let v = parse(b"(dp0\nS'raw'\np1\nS'\\x00\\x01\\\\\\'\\n\\t'\np2\nsVname\\u00e9\np3\nI1\ns.")
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
