//! `substep site serve SITE.toml`: host an experimental substructure for remote clients — the
//! project's protocol (`substep run` with `[substructure.remote]`) or OpenFresco's generic TCP
//! protocol (OpenSees `genericClient`). Each connection is logged on stdout, one line each.

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use std::io::Write;
use std::net::{TcpListener, UdpSocket};
use std::path::PathBuf;
use std::sync::Arc;
use substep::io::site_config::SiteDefinition;
use substep::site::openfresco::OpenFrescoServer;
use substep::site::{ServeOptions, SiteServer, Transport};

#[derive(Debug, Args)]
pub struct SiteArgs {
    #[command(subcommand)]
    pub command: SiteCommand,
}

#[derive(Debug, Subcommand)]
pub enum SiteCommand {
    /// Serve the experimental substructure of SITE.toml (see docs/config.md, "Site")
    Serve(ServeArgs),
}

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Site definition (TOML)
    pub config: PathBuf,
    /// Return after the first client disconnects (default: serve forever)
    #[arg(long)]
    pub once: bool,
    /// Override `[site] listen` (e.g. 127.0.0.1:0 for a free port; the log shows the port)
    #[arg(long, value_name = "ADDR")]
    pub listen: Option<String>,
}

fn bind_error(addr: &str, e: std::io::Error) -> anyhow::Error {
    substep::Error::invalid("site.listen", format!("cannot listen on {addr}: {e}")).into()
}

pub fn site(args: &SiteArgs) -> Result<()> {
    let SiteCommand::Serve(a) = &args.command;
    let def = SiteDefinition::from_file(&a.config)?;
    let listen = a.listen.clone().unwrap_or_else(|| def.listen().to_string());
    let log: Arc<dyn Fn(&str) + Send + Sync> = Arc::new(|line: &str| {
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "{line}");
        let _ = out.flush();
    });
    let report = match def {
        SiteDefinition::Substep {
            transport,
            idle_timeout,
            lab,
            ..
        } => {
            let options = ServeOptions {
                once: a.once,
                idle_timeout,
                log: Some(log),
                ..ServeOptions::default()
            };
            match transport {
                Transport::Tcp => {
                    let listener = TcpListener::bind(&listen).map_err(|e| bind_error(&listen, e))?;
                    SiteServer::serve(listener, lab.factory(), &options)?
                }
                Transport::Udp => {
                    let socket = UdpSocket::bind(&listen).map_err(|e| bind_error(&listen, e))?;
                    SiteServer::serve_udp(socket, lab.factory(), &options)?
                }
            }
        }
        SiteDefinition::OpenFresco {
            idle_timeout, element, ..
        } => {
            let options = ServeOptions {
                once: a.once,
                idle_timeout,
                log: Some(log),
                ..ServeOptions::default()
            };
            let listener = TcpListener::bind(&listen).map_err(|e| bind_error(&listen, e))?;
            OpenFrescoServer::serve(listener, move |_sizes| element.build(), &options)?
        }
    };
    println!("site: done ({} session(s))", report.sessions);
    std::io::stdout().flush().context("stdout")?;
    Ok(())
}
