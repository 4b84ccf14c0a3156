//! The pickle machine: a reader over the bytes, a heap of shared objects, the
//! stack, marks and memo, and the opcode loop of protocols 0-5.

use std::collections::HashMap;
use std::rc::Rc;

use super::builders::{allowed, build, call};
use super::escapes::{latin1, raw_unicode_unescape, unescape, utf8};
use super::value::Value;

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
pub fn parse(data: &[u8]) -> crate::io::Result<Value> {
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
