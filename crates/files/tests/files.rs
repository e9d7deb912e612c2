//! Atomic writes, output checks, undo and `.npy` reading under hostile input.
#![allow(clippy::unwrap_used)]

use mfm_files::{FileError, Outputs, Undo, npy, write_atomic};
use proptest::prelude::*;
use std::fs;
use std::io::Write;
use std::path::Path;

fn put(path: &Path, text: &str) -> Result<(), FileError> {
    write_atomic(path, |w| w.write_all(text.as_bytes()))
}

fn leftovers(dir: &Path) -> Vec<String> {
    fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect()
}

#[test]
fn a_symlink_is_followed_and_stays_a_link() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("target.txt");
    fs::write(&target, "old").unwrap();
    let link = dir.path().join("link.txt");
    std::os::unix::fs::symlink("target.txt", &link).unwrap();
    put(&link, "new").unwrap();
    assert!(
        fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert_eq!(fs::read_to_string(&target).unwrap(), "new");
    // a dangling link creates its target
    let dangling = dir.path().join("dangling");
    std::os::unix::fs::symlink(dir.path().join("made.txt"), &dangling).unwrap();
    put(&dangling, "made").unwrap();
    assert_eq!(
        fs::read_to_string(dir.path().join("made.txt")).unwrap(),
        "made"
    );
    assert!(leftovers(dir.path()).is_empty());
}

#[test]
fn folders_devices_and_fifos_are_refused_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let sub = dir.path().join("sub");
    fs::create_dir(&sub).unwrap();
    let e = put(&sub, "x").unwrap_err();
    assert!(
        e.to_string().contains("is a folder, not a regular file"),
        "{e}"
    );
    assert!(sub.is_dir());

    let e = put(Path::new("/dev/null"), "x").unwrap_err();
    assert!(e.to_string().contains("/dev/null is a device"), "{e}");
    use std::os::unix::fs::FileTypeExt;
    assert!(
        fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device()
    );

    let fifo = dir.path().join("fifo");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
    let e = put(&fifo, "x").unwrap_err();
    assert!(e.to_string().contains("is a FIFO"), "{e}");
    assert!(fs::metadata(&fifo).unwrap().file_type().is_fifo());
    // a link to a device is refused too
    let link = dir.path().join("null-link");
    std::os::unix::fs::symlink("/dev/null", &link).unwrap();
    assert!(matches!(put(&link, "x"), Err(FileError::NotRegular { .. })));
    assert!(leftovers(dir.path()).is_empty());
}

#[test]
fn a_failed_write_keeps_the_old_file_and_leaves_no_debris() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.txt");
    fs::write(&path, "precious").unwrap();
    let e = write_atomic(&path, |w| {
        w.write_all(b"half")?;
        Err(std::io::Error::other("disk on fire"))
    })
    .unwrap_err();
    assert!(e.to_string().contains("a.txt: disk on fire"), "{e}");
    assert_eq!(fs::read_to_string(&path).unwrap(), "precious");
    assert!(leftovers(dir.path()).is_empty());
    // an uncommitted file disappears
    {
        let mut f = mfm_files::AtomicFile::create(&path).unwrap();
        f.write_all(b"never").unwrap();
    }
    assert_eq!(fs::read_to_string(&path).unwrap(), "precious");
    assert!(leftovers(dir.path()).is_empty());
    // a rename that fails (the target became a folder meanwhile) leaves
    // no temporary file either
    let racy = dir.path().join("racy.txt");
    let mut f = mfm_files::AtomicFile::create(&racy).unwrap();
    f.write_all(b"late").unwrap();
    fs::create_dir(&racy).unwrap();
    fs::write(racy.join("inside"), "x").unwrap();
    assert!(f.commit().is_err());
    assert!(racy.join("inside").is_file());
    assert!(leftovers(dir.path()).is_empty());
    // a missing folder is an error naming the path
    let e = put(&dir.path().join("no/such/x.txt"), "x").unwrap_err();
    assert!(e.to_string().contains("no/such/x.txt"), "{e}");
}

#[test]
fn permissions_of_a_replaced_file_are_kept() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("script.sh");
    fs::write(&path, "old").unwrap();
    fs::set_permissions(&path, fs::Permissions::from_mode(0o751)).unwrap();
    put(&path, "new").unwrap();
    assert_eq!(
        fs::metadata(&path).unwrap().permissions().mode() & 0o777,
        0o751
    );
}

#[test]
fn outputs_that_are_inputs_or_collide_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mesh = d.join("in.off");
    fs::write(&mesh, "OFF").unwrap();
    let data = d.join("ref");
    fs::create_dir(&data).unwrap();
    fs::write(data.join("mesh.ply"), "ply").unwrap();

    let spelled = d.join("ref/../in.off");
    let e = Outputs::new()
        .input(&mesh)
        .output(&spelled)
        .check()
        .unwrap_err();
    assert!(matches!(e, FileError::OutputIsInput { .. }), "{e}");
    // a hard link is the same file under another name
    let hard = d.join("hard.off");
    fs::hard_link(&mesh, &hard).unwrap();
    let e = Outputs::new()
        .input(&mesh)
        .output(&hard)
        .check()
        .unwrap_err();
    assert!(matches!(e, FileError::OutputIsInput { .. }), "{e}");
    // inside an input folder, existing or not
    for out in [data.join("mesh.ply"), data.join("new/x.png")] {
        let e = Outputs::new()
            .input(&data)
            .output(&out)
            .check()
            .unwrap_err();
        assert!(matches!(e, FileError::OutputInsideInput { .. }), "{e}");
    }
    // two outputs naming one file (x.json and the .json next to x.npy)
    let out = d.join("x.json");
    let e = Outputs::new()
        .output(&out)
        .output(out.with_extension("json"))
        .check()
        .unwrap_err();
    assert!(matches!(e, FileError::SameOutput { .. }), "{e}");
    assert!(e.to_string().contains("x.json and"), "{e}");
    // an output folder is not a file
    let e = Outputs::new().output(&data).check().unwrap_err();
    assert!(matches!(e, FileError::NotRegular { .. }), "{e}");
    // distinct paths, built-in names and missing inputs pass
    Outputs::new()
        .input(&mesh)
        .input("builtin:blob")
        .input(&data)
        .output(d.join("out.npy"))
        .output(d.join("out.json"))
        .output(d.join("refs/x.png"))
        .check()
        .unwrap();
}

#[test]
fn undo_removes_only_what_it_created() {
    let dir = tempfile::tempdir().unwrap();
    let old = dir.path().join("old.txt");
    fs::write(&old, "mine").unwrap();
    let deep = dir.path().join("a/b/c");
    {
        let mut undo = Undo::new();
        undo.create_dir_all(&deep).unwrap();
        undo.file(&old);
        undo.file(dir.path().join("new.txt"));
        fs::write(dir.path().join("new.txt"), "x").unwrap();
    }
    assert!(!dir.path().join("a").exists());
    assert!(!dir.path().join("new.txt").exists());
    assert_eq!(fs::read_to_string(&old).unwrap(), "mine");
    let mut undo = Undo::new();
    undo.create_dir_all(&deep).unwrap();
    undo.keep();
    assert!(deep.is_dir());
}

#[test]
fn prepare_refuses_first_then_creates_folders_it_removes_on_failure() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.txt");
    fs::write(&input, "input").unwrap();
    // a refused output set creates nothing
    let clash = Outputs::new()
        .input(&input)
        .output(dir.path().join("new/a.txt"))
        .output(&input);
    assert!(matches!(
        clash.prepare(),
        Err(FileError::OutputIsInput { .. })
    ));
    assert!(!dir.path().join("new").exists());
    // folders are created, and removed with the outputs unless kept
    let outputs = Outputs::new()
        .input(&input)
        .output(dir.path().join("new/deep/a.txt"))
        .output(dir.path().join("b.txt"));
    {
        let _undo = outputs.prepare().unwrap();
        assert!(dir.path().join("new/deep").is_dir());
        fs::write(dir.path().join("new/deep/a.txt"), "x").unwrap();
        fs::write(dir.path().join("b.txt"), "x").unwrap();
    }
    assert!(!dir.path().join("new").exists());
    assert!(!dir.path().join("b.txt").exists());
    outputs.prepare().unwrap().keep();
    assert!(dir.path().join("new/deep").is_dir());
    // the iterator forms: None adds no input, a clash among them is found
    let none: Option<&Path> = None;
    let many = Outputs::new()
        .inputs(none)
        .inputs([&input])
        .outputs([dir.path().join("c.txt"), input.clone()]);
    assert!(matches!(many.check(), Err(FileError::OutputIsInput { .. })));
    assert!(
        Outputs::new()
            .inputs(none)
            .outputs([&input])
            .check()
            .is_ok()
    );
    assert_eq!(fs::read_to_string(&input).unwrap(), "input");
}

#[test]
fn an_output_folder_must_be_empty_and_a_taken_folder_is_emptied_on_failure() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    mfm_files::ensure_empty_dir(&out).unwrap();
    fs::create_dir(&out).unwrap();
    mfm_files::ensure_empty_dir(&out).unwrap();
    fs::write(out.join("user.txt"), "mine").unwrap();
    let e = mfm_files::ensure_empty_dir(&out).unwrap_err();
    assert!(matches!(e, FileError::NotEmpty { .. }), "{e}");
    assert!(e.to_string().contains("is not empty"), "{e}");
    // a taken folder must be empty; it is created, and all written in it
    // is removed unless kept, named in advance or not
    assert!(matches!(
        Undo::empty_folder(&out),
        Err(FileError::NotEmpty { .. })
    ));
    let fresh = dir.path().join("fresh/run");
    {
        let _undo = Undo::empty_folder(&fresh).unwrap();
        fs::create_dir(fresh.join("checkpoints")).unwrap();
        fs::write(fresh.join("checkpoints/a"), "x").unwrap();
        fs::write(fresh.join("b"), "x").unwrap();
    }
    assert!(!dir.path().join("fresh").exists());
    let empty = dir.path().join("empty");
    fs::create_dir(&empty).unwrap();
    {
        let _undo = Undo::empty_folder(&empty).unwrap();
        fs::write(empty.join("new.txt"), "x").unwrap();
    }
    assert!(empty.is_dir(), "a folder that existed stays");
    assert_eq!(fs::read_dir(&empty).unwrap().count(), 0);
    let undo = Undo::empty_folder(&empty).unwrap();
    fs::write(empty.join("kept.txt"), "x").unwrap();
    undo.keep();
    assert!(empty.join("kept.txt").is_file());
    assert_eq!(fs::read_to_string(out.join("user.txt")).unwrap(), "mine");
}

#[test]
fn npy_round_trip_and_precise_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.npy");
    let values: Vec<f64> = (0..24).map(|i| f64::from(i) * 0.5 - 3.0).collect();
    npy::write(&p, &values, &[2, 3, 4]).unwrap();
    let a = npy::read::<f64>(&p).unwrap();
    assert_eq!(a.shape, [2, 3, 4]);
    assert_eq!(a.values, values);
    let bytes = fs::read(&p).unwrap();
    assert_eq!(npy::file_bytes(&[2, 3, 4], 8), bytes.len() as u64);
    let t = dir.path().join("trunc.npy");
    fs::write(&t, &bytes[..bytes.len() - 5]).unwrap();
    let e = npy::read::<f32>(&t).unwrap_err().to_string();
    assert!(
        e.contains("trunc.npy: truncated") && e.contains("needs 192 data bytes, the file has 187"),
        "{e}"
    );
    let mut long = bytes.clone();
    long.extend_from_slice(&[0; 3]);
    fs::write(&t, &long).unwrap();
    let e = npy::read::<f32>(&t).unwrap_err().to_string();
    assert!(e.contains("3 bytes after the 192 data bytes"), "{e}");
    // a stream that stops early writes nothing
    let s = dir.path().join("s.npy");
    let mut w = npy::NpyStream::<f32>::create(&s, &[4]).unwrap();
    w.append(&[1.0, 2.0]).unwrap();
    assert!(w.append(&[0.0; 3]).is_err());
    assert!(w.finish().is_err());
    assert!(!s.exists());
    assert!(leftovers(dir.path()).is_empty());
}

#[test]
fn a_header_claiming_a_huge_shape_is_refused_before_allocating() {
    let bytes = {
        let mut v = Vec::new();
        // hand-made header: shape (100000000000, 26540) of float32, no data
        let dict = "{'descr': '<f4', 'fortran_order': False, 'shape': (100000000000, 26540), }";
        let mut text = dict.as_bytes().to_vec();
        while (text.len() + 11) % 64 != 0 {
            text.push(b' ');
        }
        text.push(b'\n');
        v.extend_from_slice(b"\x93NUMPY\x01\x00");
        v.extend_from_slice(&(text.len() as u16).to_le_bytes());
        v.extend_from_slice(&text);
        v
    };
    let e = npy::from_bytes::<f32>(&bytes).unwrap_err();
    assert!(e.contains("truncated"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Arbitrary bytes never panic and, when accepted, hold exactly what the
    /// shape says.
    #[test]
    fn npy_reader_survives_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..256)) {
        if let Ok(a) = npy::from_bytes::<f32>(&bytes) {
            prop_assert_eq!(a.values.len(), a.shape.iter().product::<usize>());
            prop_assert!(a.values.len() * 4 <= bytes.len());
        }
    }

    /// Valid files with flipped or cut bytes never panic either.
    #[test]
    fn npy_reader_survives_damaged_files(
        n in 0usize..20,
        flip in any::<proptest::sample::Index>(),
        value in any::<u8>(),
        cut in any::<proptest::sample::Index>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        let values: Vec<f32> = (0..n).map(|i| i as f32).collect();
        npy::write(&p, &values, &[n as u64, 1]).unwrap();
        let mut bytes = fs::read(&p).unwrap();
        let i = flip.index(bytes.len());
        bytes[i] = value;
        let _ = npy::from_bytes::<f64>(&bytes);
        let k = cut.index(bytes.len());
        let _ = npy::from_bytes::<f32>(&bytes[..k]);
    }
}

#[test]
fn json_is_pretty_with_a_final_newline_and_refused_like_any_output() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("summary.json");
    let value = serde_json::json!({"k": 3, "tau": 1e-300});
    mfm_files::write_json(&path, &value).unwrap();
    let text = fs::read_to_string(&path).unwrap();
    assert_eq!(
        text,
        format!("{}\n", serde_json::to_string_pretty(&value).unwrap())
    );
    let back: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(back, value);
    // a folder at the path is refused, nothing left behind
    let folder = dir.path().join("folder");
    fs::create_dir(&folder).unwrap();
    assert!(mfm_files::write_json(&folder, &value).is_err());
    assert!(leftovers(dir.path()).is_empty());
}
