//! The `camspring` command line: parses arguments, calls the library, prints, exits.
//!
//! Exit codes: 0 done (warnings allowed), 1 a design check failed (outputs still written),
//! 2 bad input (spec, arguments), 3 an output could not be written.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use camspring::run::{format_design, run_design, EXIT_BAD_INPUT, EXIT_IO};

#[derive(Parser, Debug)]
#[command(name = "camspring", version, about = "Design exponential cam springs and check them", long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Solve the law, synthesise the cam, run the checks and write the outputs.
    ///
    /// Examples:
    ///   camspring design                         # built-in default spec (specs/paper.toml)
    ///   camspring design specs/ankle.toml -o out/ankle
    ///   camspring design specs/paper.toml --json # summary on stdout
    #[command(verbatim_doc_comment)]
    Design {
        /// Spec file (TOML); the built-in default spec when omitted.
        spec: Option<PathBuf>,
        /// Output folder (default: out/<spec name>).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Print the design summary as JSON on stdout instead of the text report.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Design { spec, out, json } => match run_design(spec.as_deref(), out.as_deref()) {
            Ok(run) => {
                if json {
                    match serde_json::to_string_pretty(&run.summary) {
                        Ok(s) => println!("{s}"),
                        Err(e) => {
                            eprintln!("error: cannot encode the summary: {e}");
                            return ExitCode::from(EXIT_IO);
                        }
                    }
                } else {
                    print!("{}", format_design(&run));
                }
                ExitCode::from(run.exit_code())
            }
            Err(e) => {
                // Every message already carries its cause (key, line, OS error).
                eprintln!("error: {e}");
                ExitCode::from(if e.is_bad_input() {
                    EXIT_BAD_INPUT
                } else {
                    EXIT_IO
                })
            }
        },
    }
}
