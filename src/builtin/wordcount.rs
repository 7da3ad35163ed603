//! Storm's classic word count: `wordcount.sentences` (spout) → shuffle →
//! `wordcount.split` → fields(word) → `wordcount.count` → global →
//! `wordcount.report`, which writes `DIR/wordcount.tsv`.

use std::collections::{BTreeMap, HashMap};

use serde::{Deserialize, Serialize};
use squall_topology::fsio::write_atomic;
use squall_topology::hash::{GOLDEN_GAMMA, splitmix64_mix};
use squall_topology::{
    Bolt, BoxError, Declarer, Emitter, ParamError, Registry, Spout, SpoutStatus, TaskContext, Tuple,
};

/// The corpus sentences are drawn from.
pub const CORPUS: &[&str] = &[
    "the cow jumped over the moon",
    "an apple a day keeps the doctor away",
    "four score and seven years ago",
    "snow white and the seven dwarfs",
    "i am at two with nature",
    "the robot mapped the corridor and closed the loop",
];

/// One line of text.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Sentence {
    /// Position in the source's sequence.
    pub id: u64,
    /// The text.
    pub text: String,
}

/// One word.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Word {
    /// The word.
    pub word: String,
}

/// A word's final count from one counter task.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WordCount {
    /// The word.
    pub word: String,
    /// Occurrences.
    pub count: u64,
}

/// Registers the word-count kinds.
pub fn register(r: &mut Registry) {
    r.register_spout("wordcount.sentences", |p| {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct P {
            count: u64,
        }
        let P { count } = p.parse()?;
        Ok(Sentences { count, next: 0, text: SentenceGen::new(p.seed()) })
    });
    r.register_bolt("wordcount.split", |p| no_params(p).map(|()| Split));
    r.register_bolt("wordcount.count", |p| no_params(p).map(|()| Count::default()));
    r.register_bolt("wordcount.report", |p| no_params(p).map(|()| Report::default()));
}

fn no_params(p: &squall_topology::Params) -> Result<(), ParamError> {
    match p.table().keys().next() {
        None => Ok(()),
        Some(k) => Err(ParamError::new(format!("unknown parameter `{k}` (this kind takes none)"))),
    }
}

/// The sentences a seed yields, in order: a fixed function of the seed, so
/// a test can recompute the expected counts.
#[derive(Debug, Clone)]
pub struct SentenceGen(u64);

impl SentenceGen {
    /// The sequence for `seed`.
    pub fn new(seed: u64) -> Self {
        SentenceGen(seed ^ 0x5157_4f52_4443_4e54)
    }
}

impl Iterator for SentenceGen {
    type Item = &'static str;

    fn next(&mut self) -> Option<&'static str> {
        // SplitMix64: portable and seedable.
        self.0 = self.0.wrapping_add(GOLDEN_GAMMA);
        Some(CORPUS[(splitmix64_mix(self.0) % CORPUS.len() as u64) as usize])
    }
}

/// Emits `count` sentences drawn from [`CORPUS`] by a seeded generator.
#[derive(Debug)]
pub struct Sentences {
    count: u64,
    next: u64,
    text: SentenceGen,
}

impl Spout for Sentences {
    fn declare(&self, d: &mut Declarer) {
        d.output::<Sentence>("default");
    }

    async fn open(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        ctx.expect_emits(self.count);
        Ok(())
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        if self.next == self.count {
            return Ok(SpoutStatus::Done);
        }
        let text = self.text.next().expect("endless").to_string();
        out.emit("default", Sentence { id: self.next, text }).await?;
        self.next += 1;
        Ok(SpoutStatus::Continue)
    }
}

/// Splits sentences into words.
#[derive(Debug)]
pub struct Split;

impl Bolt for Split {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Sentence>().output::<Word>("default");
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let sentence = input.get::<Sentence>().ok_or("wordcount.split expects Sentence")?;
        for word in sentence.text.split_whitespace() {
            out.emit("default", Word { word: word.to_string() }).await?;
        }
        Ok(())
    }
}

/// Counts the words routed to it; emits the totals when the input ends.
#[derive(Debug, Default)]
pub struct Count {
    counts: HashMap<String, u64>,
}

impl Bolt for Count {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Word>().output::<WordCount>("default");
    }

    async fn execute(&mut self, input: Tuple, _out: &mut Emitter) -> Result<(), BoxError> {
        let word = input.get::<Word>().ok_or("wordcount.count expects Word")?;
        *self.counts.entry(word.word.clone()).or_default() += 1;
        Ok(())
    }

    async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        let mut words: Vec<_> = self.counts.drain().collect();
        words.sort();
        out.count("distinct_words", words.len() as u64);
        for (word, count) in words {
            out.emit("default", WordCount { word, count }).await?;
        }
        Ok(())
    }
}

/// Gathers every counter's totals and writes `wordcount.tsv` (word, count;
/// most frequent first).
#[derive(Debug, Default)]
pub struct Report {
    totals: BTreeMap<String, u64>,
    out_dir: Option<std::path::PathBuf>,
}

impl Bolt for Report {
    fn declare(&self, d: &mut Declarer) {
        d.input::<WordCount>();
    }

    async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.out_dir = ctx.out_dir().map(|p| p.to_path_buf());
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, _out: &mut Emitter) -> Result<(), BoxError> {
        let wc = input.get::<WordCount>().ok_or("wordcount.report expects WordCount")?;
        let total = self.totals.entry(wc.word.clone()).or_default();
        if *total > 0 {
            return Err(
                format!("word \"{}\" was counted by two tasks: fields grouping broken", wc.word).into()
            );
        }
        *total += wc.count;
        Ok(())
    }

    async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        out.count("words", self.totals.values().sum());
        let Some(dir) = &self.out_dir else {
            return Ok(());
        };
        let mut rows: Vec<(&String, &u64)> = self.totals.iter().collect();
        rows.sort_by(|a, b| b.1.cmp(a.1).then(a.0.cmp(b.0)));
        let mut text = String::from("word\tcount\n");
        for (word, count) in rows {
            text.push_str(&format!("{word}\t{count}\n"));
        }
        write_atomic(&dir.join("wordcount.tsv"), text.as_bytes())?;
        Ok(())
    }
}
