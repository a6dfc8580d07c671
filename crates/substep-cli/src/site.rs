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

/// Whether `listen` binds only this machine's loopback interface.
fn loopback_only(addr: &std::net::SocketAddr) -> bool {
    addr.ip().is_loopback()
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
    let server = def.server().clone();
    let options = ServeOptions {
        once: a.once,
        idle_timeout: Some(server.idle_timeout),
        handshake_timeout: server.handshake_timeout,
        limits: server.limits,
        secret: server.secret.clone(),
        allow: server.allow.clone(),
        log: Some(log),
        ..ServeOptions::default()
    };
    // Who can reach the site: warn when it is more than this machine and nothing restricts it.
    let warn = |bound: std::net::SocketAddr, openfresco: bool| {
        if loopback_only(&bound) {
            return;
        }
        if openfresco && server.allow.is_none() {
            eprintln!(
                "warning: the openfresco protocol has no authentication and {bound} is reachable from other machines: \
                 set [site] allow = [...] to the client addresses and run it on a lab network only (docs/security.md)"
            );
        } else if !openfresco && server.secret.is_none() {
            eprintln!(
                "warning: {bound} is reachable from other machines and the site has no secret: anyone who can reach it \
                 can move the actuators; set [site] secret_file or SUBSTEP_SITE_SECRET (docs/security.md)"
            );
        }
    };
    let report = match def {
        SiteDefinition::Substep { transport, lab, .. } => {
            let factory = lab.factory_with(server.limits);
            match transport {
                Transport::Tcp => {
                    let listener = TcpListener::bind(&listen).map_err(|e| bind_error(&listen, e))?;
                    if let Ok(bound) = listener.local_addr() {
                        warn(bound, false);
                    }
                    SiteServer::serve(listener, factory, &options)?
                }
                Transport::Udp => {
                    let socket = UdpSocket::bind(&listen).map_err(|e| bind_error(&listen, e))?;
                    if let Ok(bound) = socket.local_addr() {
                        warn(bound, false);
                    }
                    SiteServer::serve_udp(socket, factory, &options)?
                }
            }
        }
        SiteDefinition::OpenFresco { element, .. } => {
            let listener = TcpListener::bind(&listen).map_err(|e| bind_error(&listen, e))?;
            if let Ok(bound) = listener.local_addr() {
                warn(bound, true);
            }
            OpenFrescoServer::serve(listener, move |_sizes| element.build(), &options)?
        }
    };
    println!("site: done ({} session(s))", report.sessions);
    std::io::stdout().flush().context("stdout")?;
    Ok(())
}
