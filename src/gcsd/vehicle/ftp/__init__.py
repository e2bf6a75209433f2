"""MAVLink FTP: the pure server core (server.py), its payload format (protocol.py), the confined
filesystem (fs.py) and the virtual files (virtual.py, parampck.py). The asyncio side is
services/ftp.py."""
