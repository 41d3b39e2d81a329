//! Where long work (reading, generating, clustering) reports how far it is. The library
//! draws nothing: a binary hands in a [`ProgressSink`] (a progress bar) and libraries and
//! tests use [`Progress::hidden`].

use std::io::Read;
use std::sync::Arc;

/// Receives progress reports; implemented by the binaries (for a terminal progress bar).
pub trait ProgressSink: Send + Sync {
    /// The amount of work in all.
    fn set_length(&self, length: u64);
    /// The work done so far.
    fn set_position(&self, position: u64);
    /// `delta` more work done.
    fn inc(&self, delta: u64);
    /// What is being done.
    fn set_message(&self, message: &str);
    /// Done: the report may disappear.
    fn finish(&self);
}

/// A handle on a [`ProgressSink`], or on none; cheap to clone.
#[derive(Clone, Default)]
pub struct Progress(Option<Arc<dyn ProgressSink>>);

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() {
            "Progress(shown)"
        } else {
            "Progress(hidden)"
        })
    }
}

impl Progress {
    /// Reports go nowhere.
    pub fn hidden() -> Progress {
        Progress(None)
    }

    /// Reports go to `sink`.
    pub fn to(sink: impl ProgressSink + 'static) -> Progress {
        Progress(Some(Arc::new(sink)))
    }

    /// See [`ProgressSink::set_length`].
    pub fn set_length(&self, length: u64) {
        if let Some(sink) = &self.0 {
            sink.set_length(length);
        }
    }

    /// See [`ProgressSink::set_position`].
    pub fn set_position(&self, position: u64) {
        if let Some(sink) = &self.0 {
            sink.set_position(position);
        }
    }

    /// See [`ProgressSink::inc`].
    pub fn inc(&self, delta: u64) {
        if let Some(sink) = &self.0 {
            sink.inc(delta);
        }
    }

    /// See [`ProgressSink::set_message`].
    pub fn set_message(&self, message: &str) {
        if let Some(sink) = &self.0 {
            sink.set_message(message);
        }
    }

    /// See [`ProgressSink::finish`].
    pub fn finish(&self) {
        if let Some(sink) = &self.0 {
            sink.finish();
        }
    }

    /// `reader`, reporting each byte read as work done.
    pub fn wrap_read<R: Read>(&self, reader: R) -> ProgressRead<R> {
        ProgressRead {
            reader,
            progress: self.clone(),
        }
    }
}

/// A reader that reports the bytes it reads ([`Progress::wrap_read`]).
pub struct ProgressRead<R> {
    reader: R,
    progress: Progress,
}

impl<R: Read> Read for ProgressRead<R> {
    fn read(&mut self, buffer: &mut [u8]) -> std::io::Result<usize> {
        let read = self.reader.read(buffer)?;
        self.progress.inc(read as u64);
        Ok(read)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[derive(Default)]
    struct Log(Mutex<Vec<String>>);

    impl ProgressSink for Arc<Log> {
        fn set_length(&self, length: u64) {
            self.0.lock().unwrap().push(format!("length {length}"));
        }
        fn set_position(&self, position: u64) {
            self.0.lock().unwrap().push(format!("at {position}"));
        }
        fn inc(&self, delta: u64) {
            self.0.lock().unwrap().push(format!("+{delta}"));
        }
        fn set_message(&self, message: &str) {
            self.0.lock().unwrap().push(message.to_string());
        }
        fn finish(&self) {
            self.0.lock().unwrap().push("done".into());
        }
    }

    #[test]
    fn reports_reach_the_sink_and_a_hidden_one_takes_them_silently() {
        let log = Arc::new(Log::default());
        let progress = Progress::to(log.clone());
        progress.set_message("reading");
        progress.set_length(5);
        let mut bytes = Vec::new();
        progress
            .wrap_read(&b"hello"[..])
            .read_to_end(&mut bytes)
            .unwrap();
        progress.finish();
        assert_eq!(bytes, b"hello");
        let seen = log.0.lock().unwrap().clone();
        assert_eq!(seen[..2], ["reading", "length 5"]);
        assert_eq!(seen.last().unwrap(), "done");
        let read: u64 = seen
            .iter()
            .filter_map(|s| s.strip_prefix('+'))
            .map(|n| n.parse::<u64>().unwrap())
            .sum();
        assert_eq!(read, 5);
        Progress::hidden().inc(3);
    }
}
