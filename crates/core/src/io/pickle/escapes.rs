//! Protocol 0's text forms: Python 2's `repr` of a byte string, raw-unicode-
//! escape lines, and the two ways a string's bytes become text.

/// Decodes the body of a protocol-0 `STRING`: Python 2's `repr` of a byte
/// string (`\\`, `\'`, `\n`, `\xhh`, octal `\ooo`…). numpy arrays pickled with
/// protocol 0 carry their raw bytes this way.
pub(super) fn unescape(body: &str) -> Result<Vec<u8>, String> {
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
pub(super) fn raw_unicode_unescape(line: &str) -> Result<String, String> {
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

/// A Python 2 byte string as text, one character per byte (latin-1).
pub(super) fn latin1(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| b as char).collect()
}

/// A Python 3 string's bytes as text (UTF-8).
pub(super) fn utf8(bytes: &[u8]) -> Result<String, String> {
    String::from_utf8(bytes.to_vec()).map_err(|_| "pickle string is not UTF-8".to_string())
}
