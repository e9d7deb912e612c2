//! A restricted reader of Python pickles (protocols 0-5, binary opcodes):
//! it builds plain values, containers and tensor references, and never
//! imports or calls anything a file names.
//!
//! A pickle is a small stack program. The opcodes that make numbers,
//! strings, tuples, lists and dicts are interpreted as they are; a `GLOBAL`
//! (a `module.name` reference) becomes a symbol, and `REDUCE` (a call) is
//! evaluated only for the callables on the allow list:
//! - `collections.OrderedDict()` and `collections.Counter(dict)`: a dict;
//! - `torch._utils._rebuild_tensor_v2(storage, offset, size, stride, ...)`:
//!   a [`TensorRef`];
//! - `torch._utils._rebuild_parameter(tensor, ...)`: the tensor.
//!
//! Any other call, `NEWOBJ` or symbol used as a value becomes
//! [`Value::Object`] carrying the class's name: nothing runs, and the caller
//! decides whether the entry holding it may be ignored. `BINPERSID` with the
//! `('storage', torch.<Type>Storage, key, location, numel)` record that
//! `torch.save` writes gives the storage a tensor refers to.
//!
//! Containers live in an arena while the program runs, so objects the
//! pickle memoizes and refers to twice (`BINPUT` then `BINGET`) see the items
//! added after memoization, as in Python.

use std::rc::Rc;

use crate::error::{Result, TorchFileError};
use crate::tensor::Dtype;

/// Deepest nesting [`Value`] resolution follows (deeper data, or a
/// self-referencing container, is refused).
pub const MAX_DEPTH: usize = 256;

/// A value of an unpickled file: what the restricted reader builds.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `None`.
    None,
    /// `True` / `False`.
    Bool(bool),
    /// An integer that fits `i64`.
    Int(i64),
    /// A larger integer: its little-endian two's-complement bytes.
    BigInt(Vec<u8>),
    /// A float.
    Float(f64),
    /// A `str`.
    Str(String),
    /// `bytes`.
    Bytes(Vec<u8>),
    /// A list (also sets and frozensets).
    List(Vec<Value>),
    /// A tuple.
    Tuple(Vec<Value>),
    /// A dict, `OrderedDict` or `Counter`, in insertion order.
    Dict(Vec<(Value, Value)>),
    /// A tensor: where its elements are, not the elements.
    Tensor(TensorRef),
    /// Something the reader does not build, named by its class or
    /// callable (`module.name`).
    Object(String),
}

impl Value {
    /// The entry `key` of a dict with string keys.
    pub fn get(&self, key: &str) -> Option<&Value> {
        match self {
            Value::Dict(items) => items
                .iter()
                .find(|(k, _)| matches!(k, Value::Str(s) if s == key))
                .map(|(_, v)| v),
            _ => None,
        }
    }

    /// A short name of the value's kind, for messages (`dict`, `tensor`,
    /// `object omegaconf.DictConfig`...).
    pub fn kind(&self) -> String {
        match self {
            Value::None => "None".into(),
            Value::Bool(_) => "bool".into(),
            Value::Int(_) | Value::BigInt(_) => "int".into(),
            Value::Float(_) => "float".into(),
            Value::Str(_) => "str".into(),
            Value::Bytes(_) => "bytes".into(),
            Value::List(_) => "list".into(),
            Value::Tuple(_) => "tuple".into(),
            Value::Dict(_) => "dict".into(),
            Value::Tensor(_) => "tensor".into(),
            Value::Object(name) => format!("object {name}"),
        }
    }

    /// The first [`Value::Object`] inside this value, with its path below
    /// `prefix` (`state_dict.base_model.x` for dict keys, `list[3]` for
    /// items).
    pub fn first_object(&self, prefix: &str) -> Option<(String, String)> {
        match self {
            Value::Object(name) => Some((prefix.to_string(), name.clone())),
            Value::List(items) | Value::Tuple(items) => items
                .iter()
                .enumerate()
                .find_map(|(i, v)| v.first_object(&format!("{prefix}[{i}]"))),
            Value::Dict(items) => items.iter().find_map(|(k, v)| {
                let key = match k {
                    Value::Str(s) => s.clone(),
                    Value::Int(i) => i.to_string(),
                    other => {
                        if let Some(found) = other.first_object(&format!("{prefix} (a key)")) {
                            return Some(found);
                        }
                        format!("<{}>", other.kind())
                    }
                };
                let path = if prefix.is_empty() {
                    key
                } else {
                    format!("{prefix}.{key}")
                };
                v.first_object(&path)
            }),
            _ => None,
        }
    }
}

/// A tensor as `torch.save` records it: a view of one storage.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TensorRef {
    /// The storage's key: its record is `data/<key>` in the archive.
    pub storage: String,
    /// Element type (from the storage's class).
    pub dtype: Dtype,
    /// Elements the storage holds.
    pub storage_numel: usize,
    /// Offset of the first element, in elements.
    pub offset: usize,
    /// Shape.
    pub shape: Vec<usize>,
    /// Stride of each dimension, in elements.
    pub stride: Vec<usize>,
}

/// What the stack holds while the program runs.
#[derive(Clone, Debug)]
enum Obj {
    None,
    Bool(bool),
    Int(i64),
    BigInt(Rc<[u8]>),
    Float(f64),
    Str(Rc<str>),
    Bytes(Rc<[u8]>),
    /// A `module.name` reference (a `GLOBAL`).
    Global(Rc<str>),
    /// A container or a built value, by its arena index.
    Node(usize),
    /// A `BINPERSID` storage record.
    Storage(Rc<(String, Dtype, usize)>),
    /// The `MARK` sentinel.
    Mark,
}

#[derive(Debug)]
enum Node {
    List(Vec<Obj>),
    Tuple(Vec<Obj>),
    Dict(Vec<(Obj, Obj)>),
    Tensor(TensorRef),
    Object(String),
}

struct Machine<'a> {
    data: &'a [u8],
    pos: usize,
    stack: Vec<Obj>,
    memo: Vec<Option<Obj>>,
    arena: Vec<Node>,
}

/// Runs the pickle program `data` and returns what it builds.
///
/// # Errors
/// [`TorchFileError::Pickle`] with the byte offset for a truncated program,
/// an unknown or unsupported opcode, a malformed stack, or nesting deeper
/// than [`MAX_DEPTH`].
///
/// # Example
/// ```
/// use mfm_torchfile::pickle::{unpickle, Value};
/// // pickle.dumps({"a": [1, 2.5]}, protocol=2)
/// let bytes = b"\x80\x02}q\x00X\x01\x00\x00\x00aq\x01]q\x02(K\x01G@\x04\x00\x00\x00\x00\x00\x00es.";
/// let v = unpickle(bytes).unwrap();
/// assert_eq!(v.get("a"), Some(&Value::List(vec![Value::Int(1), Value::Float(2.5)])));
/// ```
pub fn unpickle(data: &[u8]) -> Result<Value> {
    let mut m = Machine {
        data,
        pos: 0,
        stack: Vec::new(),
        memo: Vec::new(),
        arena: Vec::new(),
    };
    let top = m.run()?;
    m.resolve(&top, 0)
}

fn err<T>(at: usize, message: impl Into<String>) -> Result<T> {
    Err(TorchFileError::Pickle {
        offset: at,
        message: message.into(),
    })
}

impl Machine<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8]> {
        let start = self.pos;
        let end = start
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or(TorchFileError::Pickle {
                offset: start,
                message: format!("the program ends inside an argument of {n} bytes"),
            })?;
        self.pos = end;
        Ok(&self.data[start..end])
    }

    fn u8(&mut self) -> Result<u8> {
        Ok(self.take(1)?[0])
    }

    fn u16(&mut self) -> Result<u16> {
        let b = self.take(2)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    fn u32(&mut self) -> Result<u32> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u64(&mut self) -> Result<u64> {
        let b = self.take(8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }

    fn line(&mut self) -> Result<String> {
        let start = self.pos;
        let rest = &self.data[start..];
        let Some(n) = rest.iter().position(|&b| b == b'\n') else {
            return err(start, "a text argument without its end of line");
        };
        self.pos = start + n + 1;
        String::from_utf8(rest[..n].to_vec()).map_err(|_| TorchFileError::Pickle {
            offset: start,
            message: "a text argument that is not UTF-8".into(),
        })
    }

    fn len_arg(&mut self, at: usize, n: u64) -> Result<usize> {
        let n = usize::try_from(n).unwrap_or(usize::MAX);
        if n > self.data.len() - self.pos.min(self.data.len()) {
            return err(
                at,
                format!("a length of {n} bytes beyond the program's end"),
            );
        }
        Ok(n)
    }

    fn text(&mut self, at: usize, n: usize) -> Result<Obj> {
        let b = self.take(n)?;
        let s = std::str::from_utf8(b).map_err(|_| TorchFileError::Pickle {
            offset: at,
            message: "a string that is not UTF-8".into(),
        })?;
        Ok(Obj::Str(Rc::from(s)))
    }

    fn pop(&mut self, at: usize) -> Result<Obj> {
        match self.stack.pop() {
            Some(Obj::Mark) | None => err(at, "an opcode needs a value the stack does not hold"),
            Some(o) => Ok(o),
        }
    }

    fn pop_mark(&mut self, at: usize) -> Result<Vec<Obj>> {
        let Some(i) = self.stack.iter().rposition(|o| matches!(o, Obj::Mark)) else {
            return err(at, "an opcode needs a MARK the stack does not hold");
        };
        let items = self.stack.split_off(i + 1);
        self.stack.pop();
        Ok(items)
    }

    fn node(&mut self, n: Node) -> Obj {
        self.arena.push(n);
        Obj::Node(self.arena.len() - 1)
    }

    fn memo_put(&mut self, at: usize, index: usize) -> Result<()> {
        let Some(top) = self.stack.last().cloned() else {
            return err(at, "memoizing an empty stack");
        };
        if matches!(top, Obj::Mark) {
            return err(at, "memoizing a MARK");
        }
        if index > self.data.len() {
            return err(
                at,
                format!("memo index {index} beyond any pickle this size"),
            );
        }
        if self.memo.len() <= index {
            self.memo.resize(index + 1, None);
        }
        self.memo[index] = Some(top);
        Ok(())
    }

    fn memo_get(&mut self, at: usize, index: usize) -> Result<()> {
        match self.memo.get(index).cloned().flatten() {
            Some(o) => {
                self.stack.push(o);
                Ok(())
            }
            None => err(at, format!("memo index {index} was never stored")),
        }
    }

    /// Adds items to the list on top of the stack (below the items).
    fn extend_list(&mut self, at: usize, items: Vec<Obj>) -> Result<()> {
        match self.stack.last() {
            Some(Obj::Node(i)) => match &mut self.arena[*i] {
                Node::List(list) => {
                    list.extend(items);
                    Ok(())
                }
                Node::Object(_) => Ok(()),
                _ => err(at, "APPEND to something that is not a list"),
            },
            _ => err(at, "APPEND to something that is not a list"),
        }
    }

    fn extend_dict(&mut self, at: usize, items: Vec<Obj>) -> Result<()> {
        if items.len() % 2 != 0 {
            return err(at, "SETITEMS with an odd number of values");
        }
        let mut pairs = Vec::with_capacity(items.len() / 2);
        let mut it = items.into_iter();
        while let (Some(k), Some(v)) = (it.next(), it.next()) {
            pairs.push((k, v));
        }
        match self.stack.last() {
            Some(Obj::Node(i)) => match &mut self.arena[*i] {
                Node::Dict(dict) => {
                    dict.extend(pairs);
                    Ok(())
                }
                Node::Object(_) => Ok(()),
                _ => err(at, "SETITEM on something that is not a dict"),
            },
            _ => err(at, "SETITEM on something that is not a dict"),
        }
    }

    fn tuple_items(&self, o: &Obj) -> Option<Vec<Obj>> {
        match o {
            Obj::Node(i) => match &self.arena[*i] {
                Node::Tuple(t) => Some(t.clone()),
                _ => None,
            },
            _ => None,
        }
    }

    fn as_usize(o: &Obj) -> Option<usize> {
        match o {
            Obj::Int(i) => usize::try_from(*i).ok(),
            _ => None,
        }
    }

    /// `REDUCE`: evaluates the allow-listed callables, records the others.
    fn call(&mut self, at: usize, callee: Obj, args: Obj) -> Result<Obj> {
        let Obj::Global(name) = callee else {
            return Ok(self.node(Node::Object("<a call of a non-global>".into())));
        };
        let args = self.tuple_items(&args);
        match (&*name, args) {
            ("collections.OrderedDict", Some(a)) if a.is_empty() => {
                Ok(self.node(Node::Dict(Vec::new())))
            }
            ("collections.OrderedDict" | "collections.Counter", Some(a)) if a.len() == 1 => {
                let items = match &a[0] {
                    Obj::Node(i) => match &self.arena[*i] {
                        Node::Dict(d) => d.clone(),
                        Node::List(l) | Node::Tuple(l) => {
                            let mut pairs = Vec::new();
                            for item in l {
                                match self.tuple_items(item) {
                                    Some(kv) if kv.len() == 2 => {
                                        pairs.push((kv[0].clone(), kv[1].clone()))
                                    }
                                    _ => {
                                        return err(
                                            at,
                                            format!(
                                                "{name} of a list that is not (key, value) pairs"
                                            ),
                                        );
                                    }
                                }
                            }
                            pairs
                        }
                        _ => return err(at, format!("{name} of something that is not a dict")),
                    },
                    _ => return err(at, format!("{name} of something that is not a dict")),
                };
                Ok(self.node(Node::Dict(items)))
            }
            ("torch._utils._rebuild_tensor_v2", Some(a)) if a.len() >= 4 => {
                let Obj::Storage(storage) = &a[0] else {
                    return err(at, "a tensor whose first argument is not a storage record");
                };
                let offset = Self::as_usize(&a[1]).ok_or(TorchFileError::Pickle {
                    offset: at,
                    message: "a tensor whose storage offset is not a non-negative integer".into(),
                })?;
                let dims = |o: &Obj, what: &str| -> Result<Vec<usize>> {
                    let items = self.tuple_items(o).ok_or(TorchFileError::Pickle {
                        offset: at,
                        message: format!("a tensor whose {what} is not a tuple"),
                    })?;
                    items
                        .iter()
                        .map(|d| {
                            Self::as_usize(d).ok_or(TorchFileError::Pickle {
                                offset: at,
                                message: format!(
                                    "a tensor whose {what} holds a negative or non-integer value"
                                ),
                            })
                        })
                        .collect()
                };
                let shape = dims(&a[2], "size")?;
                let stride = dims(&a[3], "stride")?;
                if shape.len() != stride.len() {
                    return err(
                        at,
                        format!(
                            "a tensor with {} sizes and {} strides",
                            shape.len(),
                            stride.len()
                        ),
                    );
                }
                let (key, dtype, numel) = (**storage).clone();
                Ok(self.node(Node::Tensor(TensorRef {
                    storage: key,
                    dtype,
                    storage_numel: numel,
                    offset,
                    shape,
                    stride,
                })))
            }
            ("torch._utils._rebuild_parameter", Some(a)) if !a.is_empty() => match &a[0] {
                Obj::Node(i) if matches!(self.arena[*i], Node::Tensor(_)) => Ok(a[0].clone()),
                _ => err(at, "a parameter whose data is not a tensor"),
            },
            _ => Ok(self.node(Node::Object(name.to_string()))),
        }
    }

    /// `BINPERSID`: the storage record of `torch.save`.
    fn persistent(&mut self, at: usize, pid: Obj) -> Result<Obj> {
        let Some(items) = self.tuple_items(&pid) else {
            return err(at, "a persistent id that is not a tuple");
        };
        let tag = matches!(items.first(), Some(Obj::Str(s)) if &**s == "storage");
        if !tag || items.len() != 5 {
            return err(
                at,
                "a persistent id that is not ('storage', type, key, location, numel)",
            );
        }
        let Obj::Global(class) = &items[1] else {
            return err(at, "a storage record whose type is not a class");
        };
        let dtype = Dtype::from_storage_class(class).ok_or(TorchFileError::Pickle {
            offset: at,
            message: format!("storage class {class} is not one this reader knows"),
        })?;
        let Obj::Str(key) = &items[2] else {
            return err(at, "a storage record whose key is not a string");
        };
        let numel = Self::as_usize(&items[4]).ok_or(TorchFileError::Pickle {
            offset: at,
            message: "a storage record whose size is not a non-negative integer".into(),
        })?;
        Ok(Obj::Storage(Rc::new((key.to_string(), dtype, numel))))
    }

    fn run(&mut self) -> Result<Obj> {
        loop {
            let at = self.pos;
            let op = match self.data.get(at) {
                Some(&op) => op,
                None => return err(at, "the program ends without STOP"),
            };
            self.pos += 1;
            match op {
                0x80 => {
                    let proto = self.u8()?;
                    if proto > 5 {
                        return err(
                            at,
                            format!("pickle protocol {proto} (this reader knows 0-5)"),
                        );
                    }
                }
                0x95 => {
                    self.u64()?; // FRAME: a size hint
                }
                b'.' => return self.pop(at),
                b'(' => self.stack.push(Obj::Mark),
                b'0' => {
                    self.pop(at)?;
                }
                b'1' => {
                    self.pop_mark(at)?;
                }
                b'2' => {
                    let top = self.stack.last().cloned();
                    match top {
                        Some(o) if !matches!(o, Obj::Mark) => self.stack.push(o),
                        _ => return err(at, "DUP of an empty stack"),
                    }
                }
                b'N' => self.stack.push(Obj::None),
                0x88 => self.stack.push(Obj::Bool(true)),
                0x89 => self.stack.push(Obj::Bool(false)),
                b'J' => {
                    let v = self.u32()? as i32;
                    self.stack.push(Obj::Int(i64::from(v)));
                }
                b'K' => {
                    let v = self.u8()?;
                    self.stack.push(Obj::Int(i64::from(v)));
                }
                b'M' => {
                    let v = self.u16()?;
                    self.stack.push(Obj::Int(i64::from(v)));
                }
                0x8a | 0x8b => {
                    let n = if op == 0x8a {
                        u64::from(self.u8()?)
                    } else {
                        u64::from(self.u32()?)
                    };
                    let n = self.len_arg(at, n)?;
                    let bytes = self.take(n)?.to_vec();
                    let o = match long_to_i64(&bytes) {
                        Some(v) => Obj::Int(v),
                        None => Obj::BigInt(Rc::from(bytes)),
                    };
                    self.stack.push(o);
                }
                b'I' => {
                    let line = self.line()?;
                    let o = match line.as_str() {
                        "00" => Obj::Bool(false),
                        "01" => Obj::Bool(true),
                        s => Obj::Int(s.parse().map_err(|_| TorchFileError::Pickle {
                            offset: at,
                            message: format!("INT argument {s:?} is not an integer"),
                        })?),
                    };
                    self.stack.push(o);
                }
                b'G' => {
                    let b = self.take(8)?;
                    let mut a = [0u8; 8];
                    a.copy_from_slice(b);
                    self.stack.push(Obj::Float(f64::from_be_bytes(a)));
                }
                b'X' => {
                    let n = u64::from(self.u32()?);
                    let n = self.len_arg(at, n)?;
                    let o = self.text(at, n)?;
                    self.stack.push(o);
                }
                0x8c => {
                    let n = usize::from(self.u8()?);
                    let o = self.text(at, n)?;
                    self.stack.push(o);
                }
                0x8d => {
                    let n = self.u64()?;
                    let n = self.len_arg(at, n)?;
                    let o = self.text(at, n)?;
                    self.stack.push(o);
                }
                b'T' | b'U' | b'B' | b'C' | 0x8e => {
                    let n = match op {
                        b'U' | b'C' => u64::from(self.u8()?),
                        0x8e => self.u64()?,
                        _ => u64::from(self.u32()?),
                    };
                    let n = self.len_arg(at, n)?;
                    let b: Rc<[u8]> = Rc::from(self.take(n)?);
                    self.stack.push(Obj::Bytes(b));
                }
                b')' => {
                    let o = self.node(Node::Tuple(Vec::new()));
                    self.stack.push(o);
                }
                b't' => {
                    let items = self.pop_mark(at)?;
                    let o = self.node(Node::Tuple(items));
                    self.stack.push(o);
                }
                0x85..=0x87 => {
                    let n = usize::from(op - 0x84);
                    if self.stack.len() < n {
                        return err(at, "TUPLE of more values than the stack holds");
                    }
                    let items = self.stack.split_off(self.stack.len() - n);
                    if items.iter().any(|o| matches!(o, Obj::Mark)) {
                        return err(at, "TUPLE over a MARK");
                    }
                    let o = self.node(Node::Tuple(items));
                    self.stack.push(o);
                }
                b']' | 0x8f => {
                    let o = self.node(Node::List(Vec::new()));
                    self.stack.push(o);
                }
                b'l' | 0x91 => {
                    let items = self.pop_mark(at)?;
                    let o = self.node(Node::List(items));
                    self.stack.push(o);
                }
                b'a' => {
                    let v = self.pop(at)?;
                    self.extend_list(at, vec![v])?;
                }
                b'e' | 0x90 => {
                    let items = self.pop_mark(at)?;
                    self.extend_list(at, items)?;
                }
                b'}' => {
                    let o = self.node(Node::Dict(Vec::new()));
                    self.stack.push(o);
                }
                b'd' => {
                    let items = self.pop_mark(at)?;
                    let o = self.node(Node::Dict(Vec::new()));
                    self.stack.push(o);
                    self.extend_dict(at, items)?;
                }
                b's' => {
                    let v = self.pop(at)?;
                    let k = self.pop(at)?;
                    self.extend_dict(at, vec![k, v])?;
                }
                b'u' => {
                    let items = self.pop_mark(at)?;
                    self.extend_dict(at, items)?;
                }
                b'c' => {
                    let module = self.line()?;
                    let name = self.line()?;
                    self.stack
                        .push(Obj::Global(Rc::from(format!("{module}.{name}"))));
                }
                0x93 => {
                    let name = self.pop(at)?;
                    let module = self.pop(at)?;
                    match (module, name) {
                        (Obj::Str(m), Obj::Str(n)) => {
                            self.stack.push(Obj::Global(Rc::from(format!("{m}.{n}"))))
                        }
                        _ => return err(at, "STACK_GLOBAL of values that are not strings"),
                    }
                }
                b'R' => {
                    let args = self.pop(at)?;
                    let callee = self.pop(at)?;
                    let o = self.call(at, callee, args)?;
                    self.stack.push(o);
                }
                0x81 | 0x92 => {
                    if op == 0x92 {
                        self.pop(at)?; // kwargs
                    }
                    self.pop(at)?; // args
                    let class = self.pop(at)?;
                    let name = match class {
                        Obj::Global(n) => n.to_string(),
                        _ => "<an instance of a non-global class>".into(),
                    };
                    let o = self.node(Node::Object(name));
                    self.stack.push(o);
                }
                b'b' => {
                    // BUILD: instance state. Dicts (OrderedDict attributes
                    // such as `_metadata`) keep their items; the state is
                    // dropped.
                    self.pop(at)?;
                    if self.stack.last().is_none_or(|o| matches!(o, Obj::Mark)) {
                        return err(at, "BUILD without an object");
                    }
                }
                b'Q' => {
                    let pid = self.pop(at)?;
                    let o = self.persistent(at, pid)?;
                    self.stack.push(o);
                }
                b'q' => {
                    let i = usize::from(self.u8()?);
                    self.memo_put(at, i)?;
                }
                b'r' => {
                    let i = self.u32()? as usize;
                    self.memo_put(at, i)?;
                }
                0x94 => {
                    let i = self.memo.len();
                    self.memo_put(at, i)?;
                }
                b'h' => {
                    let i = usize::from(self.u8()?);
                    self.memo_get(at, i)?;
                }
                b'j' => {
                    let i = self.u32()? as usize;
                    self.memo_get(at, i)?;
                }
                other => {
                    return err(
                        at,
                        format!("opcode 0x{other:02x} is not one this reader accepts"),
                    );
                }
            }
        }
    }

    fn resolve(&self, o: &Obj, depth: usize) -> Result<Value> {
        if depth > MAX_DEPTH {
            return err(
                self.pos,
                format!(
                    "values nested deeper than {MAX_DEPTH} levels (or a container that holds itself)"
                ),
            );
        }
        Ok(match o {
            Obj::None => Value::None,
            Obj::Bool(b) => Value::Bool(*b),
            Obj::Int(i) => Value::Int(*i),
            Obj::BigInt(b) => Value::BigInt(b.to_vec()),
            Obj::Float(f) => Value::Float(*f),
            Obj::Str(s) => Value::Str(s.to_string()),
            Obj::Bytes(b) => Value::Bytes(b.to_vec()),
            Obj::Global(name) => Value::Object(name.to_string()),
            Obj::Storage(s) => Value::Object(format!("storage {}", s.0)),
            Obj::Mark => return err(self.pos, "a MARK left on the stack"),
            Obj::Node(i) => match &self.arena[*i] {
                Node::List(items) => Value::List(
                    items
                        .iter()
                        .map(|x| self.resolve(x, depth + 1))
                        .collect::<Result<_>>()?,
                ),
                Node::Tuple(items) => Value::Tuple(
                    items
                        .iter()
                        .map(|x| self.resolve(x, depth + 1))
                        .collect::<Result<_>>()?,
                ),
                Node::Dict(items) => Value::Dict(
                    items
                        .iter()
                        .map(|(k, v)| {
                            Ok((self.resolve(k, depth + 1)?, self.resolve(v, depth + 1)?))
                        })
                        .collect::<Result<_>>()?,
                ),
                Node::Tensor(t) => Value::Tensor(t.clone()),
                Node::Object(name) => Value::Object(name.clone()),
            },
        })
    }
}

/// A little-endian two's-complement integer (`LONG1`/`LONG4`), if it fits
/// `i64`.
fn long_to_i64(bytes: &[u8]) -> Option<i64> {
    if bytes.is_empty() {
        return Some(0);
    }
    if bytes.len() > 8 {
        let sign = if bytes[bytes.len() - 1] & 0x80 != 0 {
            0xff
        } else {
            0
        };
        if bytes[8..].iter().any(|&b| b != sign) {
            return None;
        }
        let v = long_to_i64(&bytes[..8])?;
        return ((v < 0) == (sign == 0xff)).then_some(v);
    }
    let negative = bytes[bytes.len() - 1] & 0x80 != 0;
    let mut a = if negative { [0xffu8; 8] } else { [0u8; 8] };
    a[..bytes.len()].copy_from_slice(bytes);
    Some(i64::from_le_bytes(a))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn long_integers_decode_with_their_sign() {
        assert_eq!(long_to_i64(&[]), Some(0));
        assert_eq!(long_to_i64(&[0xff]), Some(-1));
        assert_eq!(long_to_i64(&[0x00, 0x01]), Some(256));
        assert_eq!(long_to_i64(&[0xff, 0x7f]), Some(32767));
        assert_eq!(long_to_i64(&[0x00, 0x80]), Some(-32768));
        assert_eq!(long_to_i64(&i64::MIN.to_le_bytes()), Some(i64::MIN));
        assert_eq!(long_to_i64(&[0, 0, 0, 0, 0, 0, 0, 0x80, 0]), None);
        assert_eq!(long_to_i64(&[1, 0, 0, 0, 0, 0, 0, 0, 0]), Some(1));
    }

    #[test]
    fn a_call_of_an_unknown_callable_builds_nothing() {
        // pickle of os.system('echo hi') by hand: c os\nsystem\n (X 'echo hi' tR.
        let bytes = b"\x80\x02cos\nsystem\nX\x07\x00\x00\x00echo hi\x85R.";
        assert_eq!(unpickle(bytes).unwrap(), Value::Object("os.system".into()));
    }

    #[test]
    fn memoized_containers_see_later_items() {
        // d = {}; l = [d, d]; d["k"] = 1 pickled: ](}q\x00h\x00e ... build by hand:
        // EMPTY_LIST, MARK, EMPTY_DICT, BINPUT 0, BINGET 0, APPENDS, then
        // BINGET 0, 'k', 1, SETITEM, POP, STOP.
        let bytes = b"](}q\x00h\x00eh\x00X\x01\x00\x00\x00kK\x01s0.";
        let v = unpickle(bytes).unwrap();
        let d = Value::Dict(vec![(Value::Str("k".into()), Value::Int(1))]);
        assert_eq!(v, Value::List(vec![d.clone(), d]));
    }

    #[test]
    fn truncated_and_malformed_programs_are_errors() {
        for bad in [
            &b""[..],
            b"\x80\x02",
            b"X\xff\xff\xff\x7f",
            b"h\x05.",
            b"s.",
            b"\x80\x09N.",
            b"\xfe",
        ] {
            assert!(unpickle(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn a_self_referencing_list_is_refused() {
        // l = []; l.append(l)
        let bytes = b"]q\x00h\x00a.";
        assert!(unpickle(bytes).is_err());
    }

    #[test]
    fn first_object_names_the_path() {
        let v = Value::Dict(vec![(
            Value::Str("a".into()),
            Value::List(vec![Value::Int(1), Value::Object("m.C".into())]),
        )]);
        assert_eq!(v.first_object(""), Some(("a[1]".into(), "m.C".into())));
    }
}
