//! The one error type of the core. Every variant says what was wrong and how to fix it;
//! the bindings map each variant to an exception of their own.

use thiserror::Error;

/// Everything that can go wrong in the core.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum Error {
    /// An argument has the wrong shape, size or value.
    #[error("{arg}: {problem}")]
    InvalidInput {
        /// The argument's name as the user wrote it.
        arg: String,
        /// What is wrong and what to do about it.
        problem: String,
    },
    /// An argument holds NaN or infinity.
    #[error("{arg}: element {index} is not finite ({value}); remove or repair NaN/inf values before calling")]
    NonFinite {
        /// The argument's name.
        arg: String,
        /// Flat row index of the first bad element.
        index: usize,
        /// The bad value, printed.
        value: String,
    },
    /// A cloud has fewer points than the method needs.
    #[error("{arg}: has {got} points but at least {needed} are needed{hint}")]
    TooFewPoints {
        /// The argument's name.
        arg: String,
        /// How many points it had.
        got: usize,
        /// How many the method needs.
        needed: usize,
        /// Extra advice, starting with "; " or empty.
        hint: String,
    },
    /// A cloud's points do not span the dimensions the method needs.
    #[error("{arg}: the points are degenerate ({what}); {advice}")]
    Degenerate {
        /// The argument's name.
        arg: String,
        /// What kind of degeneracy: "all points equal", "collinear", ...
        what: String,
        /// What to do about it.
        advice: String,
    },
    /// A length unit that binpick does not know.
    #[error("unit: unknown unit {unit:?}; use one of \"mm\", \"cm\", \"m\", \"in\"")]
    UnknownUnit {
        /// The unit as given.
        unit: String,
    },
    /// The caller cancelled the call (Ctrl-C) before it finished; nothing it built was kept.
    #[error("the call was cancelled before it finished; nothing it built was kept")]
    Cancelled,
    /// A mesh or point-cloud file that does not exist or cannot be opened.
    #[error("{path}: cannot open the file ({reason}); check the path")]
    FileNotFound {
        /// The path as given.
        path: String,
        /// The operating system's reason.
        reason: String,
    },
    /// A mesh or point-cloud file whose content is corrupt, empty or unsupported.
    #[error("{path}: {problem}")]
    BadFile {
        /// The path as given.
        path: String,
        /// What is wrong with the content.
        problem: String,
    },
    /// Writing a file failed.
    #[error("{path}: cannot write ({reason})")]
    WriteFailed {
        /// The path as given.
        path: String,
        /// The operating system's reason.
        reason: String,
    },
    /// No object in the scene fits the model well enough.
    #[error("no object found: {reason}")]
    NoObjectFound {
        /// Why nothing was accepted.
        reason: String,
    },
}

impl Error {
    /// Shorthand for [`Error::InvalidInput`].
    pub fn invalid(arg: impl Into<String>, problem: impl Into<String>) -> Self {
        Error::InvalidInput {
            arg: arg.into(),
            problem: problem.into(),
        }
    }

    /// Shorthand for [`Error::BadFile`].
    pub fn bad_file(path: impl Into<String>, problem: impl Into<String>) -> Self {
        Error::BadFile {
            path: path.into(),
            problem: problem.into(),
        }
    }
}

/// Result alias of the core.
pub type Result<T> = std::result::Result<T, Error>;
