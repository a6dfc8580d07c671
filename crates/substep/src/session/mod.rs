//! A front end's run of a test definition, shared by the `substep` command and the Python
//! package so that both behave alike:
//!
//! * [`live`]: the live monitor page and the stability indicator around the run loop (a few
//!   calls per step; [`live::LiveObserver`] wraps any run observer);
//! * [`realtime`]: a real-time run into its output folder (runner, reference, writer thread,
//!   deadline report).
//!
//! An offline run's output folder is [`crate::output::RunFolder`].

pub mod live;
pub mod realtime;
