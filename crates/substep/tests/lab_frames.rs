//! Issue 27: the packets substep sends to a lab target, byte for byte against the frames
//! OpenFresco's C++ builds (aschellenberg74/OpenFresco, commit c34c383; docs/lab.md cites the
//! lines). Each test stands in for the target on loopback, records every byte the host sends
//! in one sub-step and at shutdown, and compares with a transcription of the C++: one send
//! buffer `sData` of 256 doubles, `newTarget = &sData[0]` and the control signals from
//! `sData[1]` (ECSpeedgoat.cpp 366–368), every `sendVector` the whole buffer in the host's byte
//! order (x86: little-endian).

use std::io::{Read, Write};
use std::net::{TcpListener, UdpSocket};
use std::time::Duration;
use substep::lab::{ChannelMap, LabProtocol, LabTarget, LabTargetSpec, LinkTransport};
use substep::substructure::ExperimentalSubstructure;

/// OpenFresco's send buffer and `sendVector`.
struct CppHost {
    s_data: [f64; 256],
    sent: Vec<Vec<u8>>,
}

impl CppHost {
    fn new() -> Self {
        Self {
            s_data: [0.0; 256],
            sent: Vec::new(),
        }
    }
    fn send_vector(&mut self) {
        self.sent
            .push(self.s_data.iter().flat_map(|x| x.to_le_bytes()).collect());
    }
}

fn spec(protocol: LabProtocol, transport: LinkTransport, address: std::net::SocketAddr) -> LabTargetSpec {
    LabTargetSpec {
        protocol,
        transport,
        address,
        local: None,
        map: ChannelMap::default_for(2),
        timeout: Duration::from_secs(2),
        hold_limit: 0,
    }
}

fn frame(words: &[f64]) -> Vec<u8> {
    let mut v: Vec<u8> = words.iter().flat_map(|x| x.to_le_bytes()).collect();
    v.resize(2048, 0);
    v
}

#[test]
fn speedgoat_frames_match_ecspeedgoat() {
    let target = UdpSocket::bind("127.0.0.1:0").unwrap();
    target.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let addr = target.local_addr().unwrap();
    let (command, dtau) = ([0.0125, -0.003], 0.001);
    let (daq_disp, daq_force) = ([0.0124, -0.0031], [250.0, -40.0]);
    let recorder = std::thread::spawn(move || {
        let mut got: Vec<Vec<u8>> = Vec::new();
        let mut buf = [0u8; 4096];
        let mut recv = |got: &mut Vec<Vec<u8>>| {
            let (n, from) = target.recv_from(&mut buf).unwrap();
            got.push(buf[..n].to_vec());
            from
        };
        // newTarget = 1 twice → switchPC = 1; newTarget = 0 twice → switchPC = 0 (the command is
        // still moving: atTarget = 0, a stale measurement the host must not take), then
        // atTarget = 1 with the measurement.
        recv(&mut got);
        let host = recv(&mut got);
        target.send_to(&frame(&[1.0, 0.0]), host).unwrap();
        recv(&mut got);
        recv(&mut got);
        target.send_to(&frame(&[0.0, 0.0, 9.0, 9.0, 9.0, 9.0]), host).unwrap();
        let words = [0.0, 1.0, daq_disp[0], daq_disp[1], daq_force[0], daq_force[1]];
        target.send_to(&frame(&words), host).unwrap();
        // Shutdown: newTarget = −1 twice.
        recv(&mut got);
        recv(&mut got);
        got
    });
    let (mut force, mut disp) = ([0.0; 2], [0.0; 2]);
    {
        let mut host = LabTarget::connect(&spec(LabProtocol::Speedgoat, LinkTransport::Udp, addr), 2).unwrap();
        host.substep(&command, (0.0, 0.0), dtau, &mut force, &mut disp).unwrap();
    }
    let got = recorder.join().unwrap();
    // The C++: control signals = the commands, then the time (substep's configuration);
    // control() (769–794): newTarget = 1, sendVector twice, wait for switchPC = 1; newTarget = 0,
    // sendVector twice, wait for switchPC = 0. The destructor (304–307): newTarget = −1, twice.
    let mut cpp = CppHost::new();
    cpp.s_data[1] = command[0];
    cpp.s_data[2] = command[1];
    cpp.s_data[3] = dtau;
    for new_target in [1.0, 0.0, -1.0] {
        cpp.s_data[0] = new_target;
        cpp.send_vector();
        cpp.send_vector();
    }
    assert_eq!(got.len(), 6);
    for (k, (a, b)) in got.iter().zip(&cpp.sent).enumerate() {
        assert_eq!(a.len(), 2048, "frame {k}");
        assert!(a == b, "frame {k} differs from ECSpeedgoat's");
    }
    // acquire() (800–803): the DAQ signals from word 2; the default map reads displacements,
    // then forces (the load cell's; the numerical substructure gets their negatives).
    assert_eq!(disp, daq_disp);
    assert_eq!(force, [-250.0, 40.0]);
}

#[test]
fn generic_tcp_frames_match_ecgenerictcp() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let (command, dtau) = ([0.02, 0.001], 0.0025);
    let daq = [0.0199, 0.0011, 125.0, -7.5];
    let recorder = std::thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let mut sizes = [0u8; 44];
        s.read_exact(&mut sizes).unwrap();
        let mut frames = Vec::new();
        for k in 0..3 {
            let mut f = vec![0u8; 2048];
            s.read_exact(&mut f).unwrap();
            frames.push(f);
            if k == 1 {
                s.write_all(&frame(&daq)).unwrap();
            }
        }
        (sizes, frames)
    });
    let (mut force, mut disp) = ([0.0; 2], [0.0; 2]);
    {
        let mut host = LabTarget::connect(&spec(LabProtocol::GenericTcp, LinkTransport::Tcp, addr), 2).unwrap();
        host.substep(&command, (0.0, 0.0), dtau, &mut force, &mut disp).unwrap();
    }
    let (sizes, got) = recorder.join().unwrap();
    // setup() (358–365): idData = sizeCtrl (disp, vel, accel, force, time), sizeDaq (the same),
    // dataSize, sent with sendID (int32 each). substep controls displacement and time and reads
    // displacement and force.
    let id_data: [i32; 11] = [2, 0, 0, 0, 1, 2, 0, 0, 2, 0, 256];
    let expected: Vec<u8> = id_data.iter().flat_map(|v| v.to_le_bytes()).collect();
    assert_eq!(sizes.to_vec(), expected);
    // control() (902–908): sData[0] = 3, the control vector from word 1 (303–323: disp, then
    // time); acquire() (911–918): sData[0] = 6 in the same buffer (the control words stay);
    // the destructor (235–236): sData[0] = 99, the same buffer again.
    let mut cpp = CppHost::new();
    cpp.s_data[1] = command[0];
    cpp.s_data[2] = command[1];
    cpp.s_data[3] = dtau;
    for code in [3.0, 6.0, 99.0] {
        cpp.s_data[0] = code;
        cpp.send_vector();
    }
    for (k, (a, b)) in got.iter().zip(&cpp.sent).enumerate() {
        assert!(a == b, "frame {k} differs from ECGenericTCP's");
    }
    // The DAQ reply from word 0: displacements (336–356), then forces.
    assert_eq!(disp, [daq[0], daq[1]]);
    assert_eq!(force, [-daq[2], -daq[3]]);
}

#[test]
fn substep_udp_frames_have_the_documented_layout() {
    let target = UdpSocket::bind("127.0.0.1:0").unwrap();
    target.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let addr = target.local_addr().unwrap();
    let recorder = std::thread::spawn(move || {
        let mut buf = [0u8; 256];
        let mut got = Vec::new();
        for k in 0..3 {
            let (n, from) = target.recv_from(&mut buf).unwrap();
            got.push(buf[..n].to_vec());
            if k < 2 {
                // A stale reply first (sequence 0: never sent), then the answer.
                let words = [k as f64 + 1.0, 1.0, 0.5, 0.25, 10.0, 20.0];
                let reply: Vec<u8> = [0.0f64, 1.0, 9.0, 9.0, 9.0, 9.0]
                    .iter()
                    .flat_map(|x| x.to_le_bytes())
                    .collect();
                target.send_to(&reply, from).unwrap();
                let reply: Vec<u8> = words.iter().flat_map(|x| x.to_le_bytes()).collect();
                target.send_to(&reply, from).unwrap();
            }
        }
        got
    });
    let (mut force, mut disp) = ([0.0; 2], [0.0; 2]);
    let stats = {
        let mut host = LabTarget::connect(&spec(LabProtocol::SubstepUdp, LinkTransport::Udp, addr), 2).unwrap();
        host.substep(&[0.1, 0.2], (0.0, 0.0), 0.004, &mut force, &mut disp)
            .unwrap();
        host.substep(&[0.3, 0.4], (0.0, 0.0), 0.004, &mut force, &mut disp)
            .unwrap();
        host.stats().clone()
    };
    let got = recorder.join().unwrap();
    let words = |f: &[u8]| -> Vec<f64> {
        f.chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect()
    };
    // [sequence, time at the end of the sub-step, Δτ, commands]; the stop is sequence −1.
    assert_eq!(words(&got[0]), [1.0, 0.004, 0.004, 0.1, 0.2]);
    assert_eq!(words(&got[1]), [2.0, 0.008, 0.004, 0.3, 0.4]);
    assert_eq!(words(&got[2])[0], -1.0);
    assert_eq!(&got[0][..8], &[0, 0, 0, 0, 0, 0, 0xF0, 0x3F]);
    assert_eq!((disp, force), ([0.5, 0.25], [-10.0, -20.0]));
    // The stray replies to sequence 0 (older than every sub-step sent, never answered) were not
    // taken for answers: counted late and discarded.
    assert_eq!((stats.late, stats.duplicated, stats.unexpected), (2, 0, 0), "{stats:?}");
    assert_eq!(stats.held, 0);
}
